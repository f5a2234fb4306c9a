"""Train and evaluate the ROI and whole-image SVM banks.

Samples (:class:`~services.labelling_training.datasets.Samples`) come from real labelled photos
(:func:`real_samples`, split by source photo with
:func:`~services.labelling_training.datasets.in_test_split`) and from simulated views
(:mod:`~services.labelling_training.sim_training`). Features are the pooled EfficientNet-Lite0
activations; each class gets a linear SVM (one-vs-all) on standardised features. The SVM ``C`` is
chosen by 3-fold cross-validation grouped by source on the training samples, and the same
out-of-fold margins fit each class's Platt scaling (a logistic regression of the label on the
margin), so the stored probabilities are calibrated on samples the SVM had not seen.
"""

from __future__ import annotations

import hashlib
import json
import logging
import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import confusion_matrix, roc_auc_score
from sklearn.model_selection import StratifiedGroupKFold
from sklearn.svm import LinearSVC

from services.labelling_training.datasets import (
    BACKGROUND,
    Samples,
    YoloSet,
    in_test_split,
    read_rgb,
    read_scene_labels,
    roi_crops,
    source_of,
)
from services.object_labelling.classifier import UNKNOWN, LabelModel, SvmBank, best_class
from services.object_labelling.cnn import FEATURE_SIZE, EfficientNetLite0, resize_for_cnn
from services.object_labelling.errors import ObjectLabellingError

log = logging.getLogger(__name__)

ROI_CLASSES = ("pallet", "forklift", "human")
SCENE_CLASSES = ("rack", "gate")
DEFAULT_C_GRID = (1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2)


class Evaluation(NamedTuple):
    """Results on held-out samples: ROC AUC per class, the ROI confusion matrix, whole-image figures.

    ``scene`` holds per whole-image class (positives, accuracy, precision, recall) at the model's
    probability threshold.
    """

    roc_auc: dict[str, float]
    confusion_rows: tuple[str, ...]  # true labels (ROI classes + background)
    confusion_cols: tuple[str, ...]  # predicted labels (ROI classes + unknown)
    confusion: npt.NDArray[np.int64]
    scene: dict[str, tuple[int, float, float, float]]
    counts: dict[str, int]
    min_probability: float

    def markdown(self) -> str:
        """The results as markdown tables."""
        lines = ["| class | held-out samples (positives) | ROC AUC |", "|---|---|---|"]
        lines += [f"| {c} | {self.counts.get(c, 0)} | {auc:.3f} |" for c, auc in self.roc_auc.items()]
        lines += [
            "",
            f"ROI decision: most probable class, `unknown` below p = {self.min_probability:g}",
            "",
            "| true \\ predicted | " + " | ".join(self.confusion_cols) + " |",
            "|---" * (len(self.confusion_cols) + 1) + "|",
        ]
        lines += [
            f"| {r} | " + " | ".join(str(v) for v in row) + " |"
            for r, row in zip(self.confusion_rows, self.confusion, strict=True)
        ]
        if self.scene:
            lines += ["", f"| whole-image class (images: {self.counts.get('scene images', 0)}) | positives | "
                      f"accuracy | precision | recall (p >= {self.min_probability:g}) |", "|---|---|---|---|---|"]
            lines += [f"| {c} | {n} | {a:.3f} | {p:.3f} | {r:.3f} |" for c, (n, a, p, r) in self.scene.items()]
        return "\n".join(lines)


class FeatureCache:
    """CNN features of images, kept in memory and optionally in an ``.npz`` file between runs.

    Keys are a hash of the image bytes, its shape and the CNN input size; the file also records the
    weights' sha256, and a cache made with other weights is ignored.
    """

    def __init__(self, net: EfficientNetLite0, weights_sha256: str, path: Path | None = None) -> None:
        self.net, self.weights_sha256, self.path = net, weights_sha256, path
        self._features: dict[str, npt.NDArray[np.float32]] = {}
        if path is not None and path.is_file():
            try:
                with np.load(path, allow_pickle=False) as data:
                    if json.loads(str(data["header"])).get("weights_sha256") == weights_sha256:
                        self._features = dict(zip(data["keys"].tolist(), data["features"], strict=True))
            except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
                log.warning("feature cache %s unreadable, starting afresh: %s", path, err)
            log.info("feature cache %s: %d entries", path, len(self._features))

    def features(self, images: Iterable[npt.NDArray[np.uint8]], size_px: int, *, batch: int = 16
                 ) -> npt.NDArray[np.float32]:
        """(n, 1280) features of (h, w, 3) uint8 RGB images resized to ``size_px``."""
        images = list(images)
        keys = [
            hashlib.blake2b(image.tobytes() + f"{image.shape}{size_px}".encode(), digest_size=16).hexdigest()
            for image in images
        ]
        todo = [i for i, key in enumerate(keys) if key not in self._features]
        for start in range(0, len(todo), batch):
            chunk = todo[start : start + batch]
            out = self.net.features(np.stack([resize_for_cnn(images[i], size_px=size_px) for i in chunk]))
            for i, row in zip(chunk, out, strict=True):
                self._features[keys[i]] = row
        if not keys:
            return np.zeros((0, FEATURE_SIZE), dtype=np.float32)
        return np.stack([self._features[key] for key in keys]).astype(np.float32)

    def save(self) -> None:
        """Write the cache file (if there is one)."""
        if self.path is None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        keys = list(self._features)
        with self.path.open("wb") as stream:
            np.savez(stream, allow_pickle=False, header=np.array(json.dumps({"weights_sha256": self.weights_sha256})),
                     keys=np.array(keys), features=np.stack([self._features[k] for k in keys]))


def real_samples(roi_sets: list[YoloSet], scene_csv: Path | None, scene_image_dir: Path | None, *, test: bool,
                 test_fraction: float = 0.3, seed: int = 0) -> Samples:
    """Samples of the real photo sets on one side of the split by source photo.

    Parameters
    ----------
    roi_sets
        YOLO sets whose boxes give ROI-class crops; background crops are sampled away from the boxes.
    scene_csv, scene_image_dir
        The whole-image label list (``filename,rack,gate``) and the folder holding those photos
        (None: no whole-image samples).
    test
        The held-out side (True) or the training side.
    test_fraction, seed
        Share of source photos held out, and the seed of the split.
    """
    crops = [
        crop
        for dataset in roi_sets
        for crop in roi_crops(dataset, seed=seed)
        if in_test_split(crop.source, test_fraction=test_fraction, seed=seed) == test
    ]
    if scene_csv is None or scene_image_dir is None:
        return Samples(crops, [], {c: np.zeros(0, np.int64) for c in SCENE_CLASSES}, [])
    rows = [
        (name, labels)
        for name, labels in read_scene_labels(scene_csv)
        if in_test_split(source_of(name), test_fraction=test_fraction, seed=seed) == test
    ]
    missing = [name for name, _ in rows if not (scene_image_dir / name).is_file()]
    if missing:
        raise ObjectLabellingError(f"{len(missing)} labelled images are not in {scene_image_dir}, e.g. {missing[0]}")
    images = [read_rgb(scene_image_dir / name) for name, _ in rows]
    labels = {c: np.array([row[c] for _, row in rows], dtype=np.int64) for c in SCENE_CLASSES}
    return Samples(crops, images, labels, [source_of(name) for name, _ in rows])


def _out_of_fold(x: npt.NDArray[np.float32], y: npt.NDArray[np.bool_],
                 folds: list[tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]], c: float) -> npt.NDArray[np.float64]:
    """SVM margins of every sample from the fold model that did not see it."""
    margins = np.zeros(y.size)
    for fit_idx, val_idx in folds:
        if y[fit_idx].all() or not y[fit_idx].any():
            raise ObjectLabellingError("a cross-validation fold has no positives or no negatives: too few sources")
        svm = LinearSVC(C=c, class_weight="balanced", max_iter=20000).fit(x[fit_idx], y[fit_idx])
        margins[val_idx] = svm.decision_function(x[val_idx])
    return margins


def _folds(targets: dict[str, npt.NDArray[np.bool_]], groups: npt.NDArray[np.str_], n_splits: int = 3
           ) -> list[tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]]:
    """Folds grouped by source and stratified by each sample's rarest positive class (or none).

    Strata with fewer than ``n_splits`` samples join the largest one, so every stratum can be spread.
    """
    names = sorted(targets, key=lambda n: int(targets[n].sum()))
    strata = np.full(groups.size, len(names))
    for k, name in reversed(list(enumerate(names))):
        strata[targets[name]] = k
    counts = np.bincount(strata, minlength=len(names) + 1)
    strata[counts[strata] < n_splits] = int(np.argmax(counts))
    splitter = StratifiedGroupKFold(n_splits=n_splits, shuffle=True, random_state=0)
    return list(splitter.split(np.zeros(groups.size), strata, groups))


def fit_bank(
    features: npt.NDArray[np.float32],
    targets: dict[str, npt.NDArray[np.bool_]],
    groups: npt.NDArray[np.str_],
    grid: tuple[float, ...],
) -> SvmBank:
    """One-vs-all SVMs with C by grouped 3-fold CV (best mean ROC AUC) and Platt scaling on the same folds."""
    for name, y in targets.items():
        if y.all() or not y.any():
            raise ObjectLabellingError(f"class {name} has no {'negatives' if y.all() else 'positives'} to train on")
        for side, members in (("positives", y), ("negatives", ~y)):
            sources = np.unique(groups[members]).size
            if sources < 3:
                raise ObjectLabellingError(
                    f"class {name} has {side} from {sources} sources; cross-validation needs at least 3"
                )
    mean = features.mean(axis=0)
    scale = features.std(axis=0) + 1e-3
    x = ((features - mean) / scale).astype(np.float32)
    folds = _folds(targets, groups)
    margins: dict[float, dict[str, npt.NDArray[np.float64]]] = {}
    best_c, best_auc = grid[0], -1.0
    for c in grid:
        margins[c] = {name: _out_of_fold(x, y, folds, c) for name, y in targets.items()}
        auc = float(np.mean([roc_auc_score(y, margins[c][name]) for name, y in targets.items()]))
        log.info("C %.0e: out-of-fold mean ROC AUC %.4f", c, auc)
        if auc > best_auc:
            best_c, best_auc = c, auc
    log.info("SVM C %.0e chosen by grouped 3-fold CV for %s", best_c, list(targets))
    coefs, intercepts, platt_a, platt_b = [], [], [], []
    for name, y in targets.items():
        # C weighs the summed hinge loss: scaled by the folds' share of the samples, the final SVM is
        # regularised like the fold SVMs, so their out-of-fold margins calibrate it
        svm = LinearSVC(C=best_c * 2 / 3, class_weight="balanced", max_iter=20000).fit(x, y)
        coefs.append(svm.coef_[0])
        intercepts.append(svm.intercept_[0])
        platt = LogisticRegression(C=1e4).fit(margins[best_c][name][:, None], y)
        platt_a.append(max(float(platt.coef_[0, 0]), 1e-6))
        platt_b.append(float(platt.intercept_[0]))
    return SvmBank(
        tuple(targets),
        np.asarray(coefs, np.float32),
        np.asarray(intercepts, np.float32),
        mean.astype(np.float32),
        scale.astype(np.float32),
        np.asarray(platt_a, np.float32),
        np.asarray(platt_b, np.float32),
    )


def train_classifier(
    samples: Samples,
    out_model_path: Path,
    *,
    net: EfficientNetLite0,
    weights_sha256: str,
    input_size_px: int = 128,
    scene_input_size_px: int = 224,
    svm_c_grid: tuple[float, ...] = DEFAULT_C_GRID,
    min_probability: float = 0.5,
    cache: FeatureCache | None = None,
) -> LabelModel:
    """Train both SVM banks on ``samples`` and write the model file.

    Parameters
    ----------
    samples
        Training samples only (ROI crops incl. background; whole images with rack/gate labels).
    out_model_path
        Where the ``.npz`` model goes.
    net, weights_sha256
        The CNN and the sha256 of its weights file (stored, checked by the worker).
    input_size_px, scene_input_size_px
        Square CNN input size for ROI crops and for whole images.
    svm_c_grid
        Linear SVM regularisation values to choose from by grouped cross-validation.
    min_probability
        Stored in the model: ROIs below it are ``unknown``, whole-image classes below it absent.
    cache
        Feature cache (a fresh in-memory one when None).
    """
    cache = cache or FeatureCache(net, weights_sha256)
    labels = np.array([c.label for c in samples.crops])
    log.info("training on %d ROI crops %s and %d whole images", len(labels),
             {k: int((labels == k).sum()) for k in (*ROI_CLASSES, BACKGROUND)}, len(samples.scene_images))
    roi_features = cache.features((c.image for c in samples.crops), input_size_px)
    roi = fit_bank(roi_features, {name: labels == name for name in ROI_CLASSES},
                    np.array([c.source for c in samples.crops]), svm_c_grid)
    scene_features = cache.features(samples.scene_images, scene_input_size_px)
    scene = fit_bank(scene_features, {name: samples.scene_labels[name] == 1 for name in SCENE_CLASSES},
                      np.array(samples.scene_sources), svm_c_grid)
    model = LabelModel(roi, scene, input_size_px, weights_sha256, min_probability, scene_input_size_px)
    out_model_path.parent.mkdir(parents=True, exist_ok=True)
    model.save(out_model_path)
    log.info("wrote classifier model %s", out_model_path)
    return model


def evaluate_classifier(model: LabelModel, samples: Samples, *, cache: FeatureCache) -> Evaluation:
    """Per-class ROC AUC, the ROI confusion matrix and whole-image figures on held-out ``samples``.

    ROI: each class's score against all other crops (other classes and background); the confusion
    matrix uses the model's decision rule without a size prior (photos have no depth): the most
    probable class, ``unknown`` below ``min_probability``. Whole-image classes: ROC AUC, and
    accuracy, precision and recall of "present" (probability at least ``min_probability``).
    """
    labels = np.array([c.label for c in samples.crops])
    scores = model.roi.scores(cache.features((c.image for c in samples.crops), model.input_size_px))
    auc = {name: float(roc_auc_score(labels == name, scores[:, i])) if 0 < (labels == name).sum() < labels.size
           else float("nan") for i, name in enumerate(model.roi.classes)}
    predicted = best_class(model.roi.probabilities(scores), model.roi.classes, min_probability=model.min_probability)
    rows, cols = (*model.roi.classes, BACKGROUND), (*model.roi.classes, UNKNOWN)
    order = sorted(set(rows) | set(cols))
    matrix = confusion_matrix(labels, predicted, labels=order)
    matrix = matrix[np.ix_([order.index(r) for r in rows], [order.index(c) for c in cols])]
    counts = {name: int((labels == name).sum()) for name in rows}
    scene: dict[str, tuple[int, float, float, float]] = {}
    if samples.scene_images:
        bank = model.scene
        scene_scores = bank.scores(cache.features(samples.scene_images, model.scene_input_size_px))
        present = bank.probabilities(scene_scores) >= model.min_probability
        for i, name in enumerate(bank.classes):
            truth = samples.scene_labels[name] == 1
            counts[name] = int(truth.sum())
            auc[name] = float(roc_auc_score(truth, scene_scores[:, i])) if 0 < truth.sum() < truth.size \
                else float("nan")
            hits = int((present[:, i] & truth).sum())
            scene[name] = (int(truth.sum()), float((present[:, i] == truth).mean()),
                           hits / max(int(present[:, i].sum()), 1), hits / max(int(truth.sum()), 1))
        counts["scene images"] = len(samples.scene_images)
    return Evaluation(auc, rows, cols, matrix.astype(np.int64), scene, counts, model.min_probability)
