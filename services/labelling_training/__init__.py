"""Training the object-labelling classifier: real labelled photos and simulator renders.

Kept apart from :mod:`services.object_labelling` (the runtime stage) so that the stage never imports the
simulator; this package may import both.
"""

from services.labelling_training.datasets import (
    BACKGROUND,
    Crop,
    Samples,
    YoloSet,
    in_test_split,
    read_scene_labels,
    roi_crops,
    source_of,
)
from services.labelling_training.training import (
    ROI_CLASSES,
    SCENE_CLASSES,
    Evaluation,
    FeatureCache,
    evaluate_classifier,
    fit_bank,
    real_samples,
    train_classifier,
)

__all__ = [
    "BACKGROUND",
    "ROI_CLASSES",
    "SCENE_CLASSES",
    "Crop",
    "Evaluation",
    "FeatureCache",
    "Samples",
    "YoloSet",
    "evaluate_classifier",
    "fit_bank",
    "in_test_split",
    "read_scene_labels",
    "real_samples",
    "roi_crops",
    "source_of",
    "train_classifier",
]
