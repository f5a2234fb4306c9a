"""One-vs-all linear SVM banks over CNN features, and the versioned model file a worker loads.

Each SVM's margin is turned into a probability by Platt scaling, ``p = 1 / (1 + exp(-(a s + b)))``,
with ``a`` and ``b`` fitted on out-of-fold margins of the training split (see
:mod:`~services.labelling_training.training`), so one threshold (``min_probability``) means the same
for every class: a proposal is ``unknown`` unless some allowed class is at least that likely.

The model file is a numpy ``.npz`` written and read without pickle: per bank the class names,
weights, intercepts, feature standardisation and Platt parameters, plus a JSON header (format
version, CNN input size, sha256 of the CNN weights the features came from, probability threshold).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from services.object_labelling.errors import ObjectLabellingError

MODEL_FORMAT = "aisle-object-labelling-svm"
MODEL_VERSION = 2
UNKNOWN = "unknown"


@dataclass(frozen=True)
class SvmBank:
    """Linear one-vs-all SVMs ``score = ((x - mean) / scale) @ coef.T + intercept``, one row per class,
    with Platt parameters ``platt_a``, ``platt_b`` (k,) turning scores into probabilities."""

    classes: tuple[str, ...]
    coef: npt.NDArray[np.float32]  # (k, d)
    intercept: npt.NDArray[np.float32]  # (k,)
    mean: npt.NDArray[np.float32]  # (d,)
    scale: npt.NDArray[np.float32]  # (d,)
    platt_a: npt.NDArray[np.float32]  # (k,), > 0
    platt_b: npt.NDArray[np.float32]  # (k,)

    def __post_init__(self) -> None:
        k, d = len(self.classes), self.mean.shape[0]
        if (
            self.coef.shape != (k, d)
            or self.intercept.shape != (k,)
            or self.scale.shape != (d,)
            or self.platt_a.shape != (k,)
            or self.platt_b.shape != (k,)
        ):
            raise ObjectLabellingError(
                f"SVM bank shapes disagree: {k} classes, coef {self.coef.shape}, intercept "
                f"{self.intercept.shape}, mean {self.mean.shape}, scale {self.scale.shape}, "
                f"Platt {self.platt_a.shape} {self.platt_b.shape}"
            )
        finite = all(np.isfinite(a).all() for a in (self.coef, self.intercept, self.platt_a, self.platt_b))
        if not (finite and (self.scale > 0).all() and (self.platt_a > 0).all()):
            raise ObjectLabellingError(
                "SVM bank holds non-finite weights, non-positive feature scales or non-positive Platt slopes"
            )

    def scores(self, features: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Signed SVM margins (n, k) of (n, d) features; > 0 means "this class" for that SVM."""
        if features.ndim != 2 or features.shape[1] != self.mean.shape[0]:
            raise ObjectLabellingError(f"features must be (n, {self.mean.shape[0]}), got {features.shape}")
        return np.asarray(((features - self.mean) / self.scale) @ self.coef.T + self.intercept, dtype=np.float32)

    def probabilities(self, scores: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Calibrated one-vs-all probabilities (n, k) in (0, 1) of :meth:`scores` output."""
        return np.asarray(1.0 / (1.0 + np.exp(-(scores * self.platt_a + self.platt_b))), dtype=np.float32)


def best_class(
    probabilities: npt.NDArray[np.float32], classes: tuple[str, ...], *, min_probability: float
) -> list[str]:
    """Per row, the most probable class, or ``"unknown"`` when its probability is below ``min_probability``."""
    best = np.argmax(probabilities, axis=1)
    top = probabilities[np.arange(probabilities.shape[0]), best]
    return [classes[b] if p >= min_probability else UNKNOWN for b, p in zip(best, top, strict=True)]


@dataclass(frozen=True)
class LabelModel:
    """Both SVM banks (ROI classes and whole-image classes) and how their features were made
    (``input_size_px``: CNN input size for ROIs)."""

    roi: SvmBank
    scene: SvmBank
    input_size_px: int
    weights_sha256: str
    min_probability: float = 0.5
    """A ROI is ``unknown`` and a whole-image class absent below this calibrated probability."""
    scene_input_size_px: int = 224
    """CNN input size for whole images (computed only when the image changed, so it can be larger)."""

    def save(self, path: str | Path) -> None:
        """Write the model as an ``.npz`` (no pickle)."""
        header = {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "input_size_px": self.input_size_px,
            "scene_input_size_px": self.scene_input_size_px,
            "weights_sha256": self.weights_sha256,
            "min_probability": self.min_probability,
            "roi_classes": list(self.roi.classes),
            "scene_classes": list(self.scene.classes),
        }
        arrays = {"header": np.array(json.dumps(header))}
        for name, bank in (("roi", self.roi), ("scene", self.scene)):
            arrays |= {
                f"{name}_coef": bank.coef,
                f"{name}_intercept": bank.intercept,
                f"{name}_mean": bank.mean,
                f"{name}_scale": bank.scale,
                f"{name}_platt_a": bank.platt_a,
                f"{name}_platt_b": bank.platt_b,
            }
        with Path(path).open("wb") as stream:
            np.savez(stream, allow_pickle=False, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> LabelModel:
        """Read a model written by :meth:`save`; a missing, foreign or corrupt file raises ObjectLabellingError."""
        path = Path(path)
        if not path.is_file():
            raise ObjectLabellingError(f"classifier model {path} does not exist")
        if not zipfile.is_zipfile(path):
            raise ObjectLabellingError(f"classifier model {path} is corrupt or not a model file (not an .npz archive)")
        try:
            with path.open("rb") as stream, np.load(stream, allow_pickle=False) as data:
                arrays = {key: data[key] for key in data.files}
            header: dict[str, Any] = json.loads(str(arrays["header"]))
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as err:
            raise ObjectLabellingError(f"classifier model {path} is corrupt or not a model file: {err}") from err
        if header.get("format") != MODEL_FORMAT or header.get("version") != MODEL_VERSION:
            raise ObjectLabellingError(
                f"classifier model {path} is {header.get('format')} v{header.get('version')}, "
                f"expected {MODEL_FORMAT} v{MODEL_VERSION} (retrain it)"
            )
        try:
            banks = {
                name: SvmBank(
                    tuple(header[f"{name}_classes"]),
                    arrays[f"{name}_coef"].astype(np.float32),
                    arrays[f"{name}_intercept"].astype(np.float32),
                    arrays[f"{name}_mean"].astype(np.float32),
                    arrays[f"{name}_scale"].astype(np.float32),
                    arrays[f"{name}_platt_a"].astype(np.float32),
                    arrays[f"{name}_platt_b"].astype(np.float32),
                )
                for name in ("roi", "scene")
            }
            return cls(
                banks["roi"],
                banks["scene"],
                int(header["input_size_px"]),
                str(header["weights_sha256"]),
                float(header["min_probability"]),
                int(header["scene_input_size_px"]),
            )
        except KeyError as err:
            raise ObjectLabellingError(f"classifier model {path} lacks {err.args[0]}") from err
