"""Train and evaluate the ROI and whole-image SVM banks on real labelled photos.

Samples are split by source photo (:func:`~services.object_labelling.datasets.in_test_split`),
features are the pooled EfficientNet-Lite0 activations, and each class gets a linear SVM
(one-vs-all) on standardised features. ``evaluate_classifier`` scores the held-out split only.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from sklearn.metrics import confusion_matrix, roc_auc_score
from sklearn.model_selection import GroupKFold
from sklearn.svm import LinearSVC

from services.object_labelling.classifier import UNKNOWN, LabelModel, SvmBank, best_class
from services.object_labelling.cnn import EfficientNetLite0, resize_for_cnn
from services.object_labelling.datasets import (
    BACKGROUND,
    Crop,
    YoloSet,
    in_test_split,
    read_rgb,
    read_scene_labels,
    roi_crops,
    source_of,
)
from services.object_labelling.errors import ObjectLabellingError

log = logging.getLogger(__name__)

ROI_CLASSES = ("pallet", "forklift", "human")
SCENE_CLASSES = ("rack", "gate")


class Evaluation(NamedTuple):
    """Held-out results: ROC AUC per class, the ROI confusion matrix and the sample counts."""

    roc_auc: dict[str, float]
    confusion_rows: tuple[str, ...]  # true labels (ROI classes + background)
    confusion_cols: tuple[str, ...]  # predicted labels (ROI classes + unknown)
    confusion: npt.NDArray[np.int64]
    scene_accuracy: dict[str, float]
    counts: dict[str, int]

    def markdown(self) -> str:
        """The results as markdown tables."""
        lines = ["| class | held-out samples (positives) | ROC AUC |", "|---|---|---|"]
        lines += [f"| {c} | {self.counts.get(c, 0)} | {auc:.3f} |" for c, auc in self.roc_auc.items()]
        lines += [
            "",
            "| true \\ predicted | " + " | ".join(self.confusion_cols) + " |",
            "|---" * (len(self.confusion_cols) + 1) + "|",
        ]
        lines += [
            f"| {r} | " + " | ".join(str(v) for v in row) + " |"
            for r, row in zip(self.confusion_rows, self.confusion, strict=True)
        ]
        if self.scene_accuracy:
            lines += ["", "| whole-image class | accuracy at score 0 |", "|---|---|"]
            lines += [f"| {c} | {a:.3f} |" for c, a in self.scene_accuracy.items()]
        return "\n".join(lines)


def _features(
    net: EfficientNetLite0, images: Iterable[npt.NDArray[np.uint8]], size_px: int, batch: int = 16
) -> npt.NDArray[np.float32]:
    resized = [resize_for_cnn(image, size_px=size_px) for image in images]
    if not resized:
        return np.zeros((0, 1280), dtype=np.float32)
    return np.concatenate([net.features(np.stack(resized[i : i + batch])) for i in range(0, len(resized), batch)])


def _roi_samples(sets: Iterable[YoloSet], *, test: bool, test_fraction: float, seed: int) -> list[Crop]:
    return [
        crop
        for dataset in sets
        for crop in roi_crops(dataset, seed=seed)
        if in_test_split(crop.source, test_fraction=test_fraction, seed=seed) == test
    ]


def _scene_samples(
    csv_path: Path, image_dir: Path, *, test: bool, test_fraction: float, seed: int
) -> tuple[list[npt.NDArray[np.uint8]], dict[str, npt.NDArray[np.int64]], npt.NDArray[np.str_]]:
    rows = [
        (name, labels)
        for name, labels in read_scene_labels(csv_path)
        if in_test_split(source_of(name), test_fraction=test_fraction, seed=seed) == test
    ]
    missing = [name for name, _ in rows if not (image_dir / name).is_file()]
    if missing:
        raise ObjectLabellingError(f"{len(missing)} labelled images are not in {image_dir}, e.g. {missing[0]}")
    images = [read_rgb(image_dir / name) for name, _ in rows]
    sources = np.array([source_of(name) for name, _ in rows])
    return images, {c: np.array([labels[c] for _, labels in rows]) for c in SCENE_CLASSES}, sources


def _select_c(
    x: npt.NDArray[np.float32],
    targets: dict[str, npt.NDArray[np.bool_]],
    groups: npt.NDArray[np.str_],
    grid: tuple[float, ...],
) -> float:
    """The SVM C with the best mean ROC AUC over 3 folds grouped by source photo (training split only)."""
    folds = list(GroupKFold(n_splits=3).split(x, groups=groups))
    best_c, best_auc = grid[0], -1.0
    for c in grid:
        aucs = []
        for fit_idx, val_idx in folds:
            for y in targets.values():
                if y[fit_idx].all() or not y[fit_idx].any() or y[val_idx].all() or not y[val_idx].any():
                    continue
                svm = LinearSVC(C=c, class_weight="balanced", max_iter=20000).fit(x[fit_idx], y[fit_idx])
                aucs.append(roc_auc_score(y[val_idx], svm.decision_function(x[val_idx])))
        if aucs and float(np.mean(aucs)) > best_auc:
            best_c, best_auc = c, float(np.mean(aucs))
    log.info("SVM C %.0e chosen by grouped 3-fold CV (mean ROC AUC %.4f)", best_c, best_auc)
    return best_c


def _fit_bank(
    features: npt.NDArray[np.float32],
    targets: dict[str, npt.NDArray[np.bool_]],
    groups: npt.NDArray[np.str_],
    grid: tuple[float, ...],
) -> SvmBank:
    mean = features.mean(axis=0)
    scale = features.std(axis=0) + 1e-3
    x = (features - mean) / scale
    for name, y in targets.items():
        if y.all() or not y.any():
            raise ObjectLabellingError(f"class {name} has no {'negatives' if y.all() else 'positives'} to train on")
    c = _select_c(x, targets, groups, grid) if len(grid) > 1 else grid[0]
    coefs, intercepts = [], []
    for y in targets.values():
        svm = LinearSVC(C=c, class_weight="balanced", max_iter=20000).fit(x, y)
        coefs.append(svm.coef_[0])
        intercepts.append(svm.intercept_[0])
    return SvmBank(
        tuple(targets),
        np.asarray(coefs, np.float32),
        np.asarray(intercepts, np.float32),
        mean.astype(np.float32),
        scale.astype(np.float32),
    )


def train_classifier(
    roi_sets: list[YoloSet],
    scene_csv: Path,
    scene_image_dir: Path,
    out_model_path: Path,
    *,
    weights_path: Path,
    input_size_px: int = 128,
    test_fraction: float = 0.3,
    svm_c_grid: tuple[float, ...] = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2),
    min_score: float = 0.0,
    seed: int = 0,
) -> LabelModel:
    """Train both SVM banks on the training split and write the model file.

    Parameters
    ----------
    roi_sets
        YOLO sets whose boxes give ROI-class crops (pallet, forklift, human); background crops are
        sampled away from the boxes.
    scene_csv, scene_image_dir
        The whole-image label list (``filename,rack,gate``) and the folder holding those photos.
    out_model_path
        Where the ``.npz`` model goes.
    weights_path
        EfficientNet-Lite0 checkpoint (``efficientnet-lite0-<sha256 prefix>.pth``).
    input_size_px
        Square CNN input size for crops and whole images.
    test_fraction
        Share of source photos held out (never trained on); the same seed must be given to
        :func:`evaluate_classifier`.
    svm_c_grid
        Linear SVM regularisation values; each bank takes the one with the best ROC AUC in a
        3-fold cross-validation grouped by source photo on the training split.
    min_score
        Stored in the model: ROI scores below it become ``"unknown"``.
    """
    net = EfficientNetLite0.load(weights_path)
    crops = _roi_samples(roi_sets, test=False, test_fraction=test_fraction, seed=seed)
    labels = np.array([c.label for c in crops])
    log.info(
        "training on %d ROI crops: %s", len(crops), {k: int((labels == k).sum()) for k in (*ROI_CLASSES, BACKGROUND)}
    )
    roi_features = _features(net, (c.image for c in crops), input_size_px)
    sources = np.array([c.source for c in crops])
    roi = _fit_bank(roi_features, {name: labels == name for name in ROI_CLASSES}, sources, svm_c_grid)
    images, scene_labels, scene_sources = _scene_samples(
        scene_csv, scene_image_dir, test=False, test_fraction=test_fraction, seed=seed
    )
    scene_features = _features(net, images, input_size_px)
    scene_targets = {name: scene_labels[name] == 1 for name in SCENE_CLASSES}
    scene = _fit_bank(scene_features, scene_targets, scene_sources, svm_c_grid)
    model = LabelModel(
        roi, scene, input_size_px, hashlib.sha256(Path(weights_path).read_bytes()).hexdigest(), min_score
    )
    model.save(out_model_path)
    log.info("wrote classifier model %s", out_model_path)
    return model


def evaluate_classifier(
    model_path: Path,
    roi_sets: list[YoloSet],
    scene_csv: Path,
    scene_image_dir: Path,
    *,
    weights_path: Path,
    test_fraction: float = 0.3,
    seed: int = 0,
) -> Evaluation:
    """Per-class ROC AUC and the ROI confusion matrix on the held-out split (same seed as training).

    ROI: each class's SVM score against all other held-out crops (other classes and background);
    the confusion matrix uses the model's decision rule (best score, ``unknown`` below
    ``min_score``). Whole-image classes: ROC AUC and accuracy at score 0 on held-out labelled photos.
    """
    model = LabelModel.load(model_path)
    net = EfficientNetLite0.load(weights_path)
    crops = _roi_samples(roi_sets, test=True, test_fraction=test_fraction, seed=seed)
    labels = np.array([c.label for c in crops])
    scores = model.roi.scores(_features(net, (c.image for c in crops), model.input_size_px))
    auc = {name: float(roc_auc_score(labels == name, scores[:, i])) for i, name in enumerate(model.roi.classes)}
    predicted = best_class(scores, model.roi.classes, min_score=model.min_score)
    rows, cols = (*model.roi.classes, BACKGROUND), (*model.roi.classes, UNKNOWN)
    matrix = confusion_matrix(labels, predicted, labels=sorted(set(rows) | set(cols)))
    order = sorted(set(rows) | set(cols))
    matrix = matrix[np.ix_([order.index(r) for r in rows], [order.index(c) for c in cols])]
    counts = {name: int((labels == name).sum()) for name in rows}
    images, scene_labels, _ = _scene_samples(
        scene_csv, scene_image_dir, test=True, test_fraction=test_fraction, seed=seed
    )
    scene_scores = model.scene.scores(_features(net, images, model.input_size_px))
    accuracy = {}
    for i, name in enumerate(model.scene.classes):
        truth = scene_labels[name] == 1
        counts[name] = int(truth.sum())
        auc[name] = float(roc_auc_score(truth, scene_scores[:, i])) if 0 < truth.sum() < truth.size else float("nan")
        accuracy[name] = float(((scene_scores[:, i] >= 0) == truth).mean())
    counts["scene images"] = len(images)
    return Evaluation(auc, rows, cols, matrix.astype(np.int64), accuracy, counts)
