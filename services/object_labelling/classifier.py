"""One-vs-all linear SVM banks over CNN features, and the versioned model file a worker loads.

The model file is a numpy ``.npz`` written and read without pickle: per bank the class names,
weights, intercepts and feature standardisation, plus a JSON header (format version, CNN input
size, sha256 of the CNN weights the features came from, score threshold).
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
MODEL_VERSION = 1
UNKNOWN = "unknown"


@dataclass(frozen=True)
class SvmBank:
    """Linear one-vs-all SVMs ``score = ((x - mean) / scale) @ coef.T + intercept``, one row per class."""

    classes: tuple[str, ...]
    coef: npt.NDArray[np.float32]  # (k, d)
    intercept: npt.NDArray[np.float32]  # (k,)
    mean: npt.NDArray[np.float32]  # (d,)
    scale: npt.NDArray[np.float32]  # (d,)

    def __post_init__(self) -> None:
        k, d = len(self.classes), self.mean.shape[0]
        if self.coef.shape != (k, d) or self.intercept.shape != (k,) or self.scale.shape != (d,):
            raise ObjectLabellingError(
                f"SVM bank shapes disagree: {k} classes, coef {self.coef.shape}, intercept "
                f"{self.intercept.shape}, mean {self.mean.shape}, scale {self.scale.shape}"
            )
        if not (np.isfinite(self.coef).all() and np.isfinite(self.intercept).all() and (self.scale > 0).all()):
            raise ObjectLabellingError("SVM bank holds non-finite weights or non-positive feature scales")

    def scores(self, features: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Signed SVM margins (n, k) of (n, d) features; > 0 means "this class" for that SVM."""
        if features.ndim != 2 or features.shape[1] != self.mean.shape[0]:
            raise ObjectLabellingError(f"features must be (n, {self.mean.shape[0]}), got {features.shape}")
        return np.asarray(((features - self.mean) / self.scale) @ self.coef.T + self.intercept, dtype=np.float32)


def best_class(scores: npt.NDArray[np.float32], classes: tuple[str, ...], *, min_score: float) -> list[str]:
    """Per row, the class with the highest score, or ``"unknown"`` when that score is below ``min_score``."""
    best = np.argmax(scores, axis=1)
    top = scores[np.arange(scores.shape[0]), best]
    return [classes[b] if s >= min_score else UNKNOWN for b, s in zip(best, top, strict=True)]


@dataclass(frozen=True)
class LabelModel:
    """Both SVM banks (ROI classes and whole-image classes) and how their features were made."""

    roi: SvmBank
    scene: SvmBank
    input_size_px: int
    weights_sha256: str
    min_score: float

    def save(self, path: str | Path) -> None:
        """Write the model as an ``.npz`` (no pickle)."""
        header = {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "input_size_px": self.input_size_px,
            "weights_sha256": self.weights_sha256,
            "min_score": self.min_score,
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
            }
        with Path(path).open("wb") as stream:
            np.savez(stream, allow_pickle=False, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> LabelModel:
        """Read a model written by :meth:`save`; a missing, foreign or corrupt file raises ObjectLabellingError."""
        path = Path(path)
        if not path.is_file():
            raise ObjectLabellingError(f"classifier model {path} does not exist")
        try:
            with path.open("rb") as stream, np.load(stream, allow_pickle=False) as data:
                arrays = {key: data[key] for key in data.files}
            header: dict[str, Any] = json.loads(str(arrays["header"]))
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as err:
            raise ObjectLabellingError(f"classifier model {path} is corrupt or not a model file: {err}") from err
        if header.get("format") != MODEL_FORMAT or header.get("version") != MODEL_VERSION:
            raise ObjectLabellingError(
                f"classifier model {path} is {header.get('format')} v{header.get('version')}, "
                f"expected {MODEL_FORMAT} v{MODEL_VERSION}"
            )
        try:
            banks = {
                name: SvmBank(
                    tuple(header[f"{name}_classes"]),
                    arrays[f"{name}_coef"].astype(np.float32),
                    arrays[f"{name}_intercept"].astype(np.float32),
                    arrays[f"{name}_mean"].astype(np.float32),
                    arrays[f"{name}_scale"].astype(np.float32),
                )
                for name in ("roi", "scene")
            }
            return cls(
                banks["roi"],
                banks["scene"],
                int(header["input_size_px"]),
                str(header["weights_sha256"]),
                float(header["min_score"]),
            )
        except KeyError as err:
            raise ObjectLabellingError(f"classifier model {path} lacks {err.args[0]}") from err
