"""The stage's recogniser: the EfficientNet-Lite0 CNN and the SVM model trained on its features, checked to
belong together; errors say how to get a model (none is shipped: photo licences)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from services.object_labelling.classifier import LabelModel
from services.object_labelling.cnn import EfficientNetLite0, default_weights_path
from services.object_labelling.errors import ObjectLabellingError
from shared.settings import Settings

TRAIN_HINT = (
    "train one with `aisle train-classifier --data ../shared/data/images` (real photos and simulator renders) "
    "or `aisle train-classifier` (simulator renders only); it writes labelling.model_path (see "
    "docs/object_labelling.md)"
)


def load_recogniser(model_path: Path, weights_path: Path | None) -> tuple[EfficientNetLite0, LabelModel]:
    """The CNN and the SVM model, checked to belong together; errors say how to get a model."""
    try:
        model = LabelModel.load(model_path)
    except ObjectLabellingError as err:
        raise ObjectLabellingError(f"{err}; {TRAIN_HINT}") from err
    weights = weights_path or default_weights_path()
    net = EfficientNetLite0.load(weights)
    if model.weights_sha256:
        digest = hashlib.sha256(weights.read_bytes()).hexdigest()
        if digest != model.weights_sha256:
            raise ObjectLabellingError(
                f"classifier model {model_path} was trained on CNN weights {model.weights_sha256[:12]}..., "
                f"but {weights} is {digest[:12]}...; {TRAIN_HINT}"
            )
    return net, model


def model_file(model_path: Path, *, data_dir: Path) -> Path:
    """``model_path`` if absolute, else under ``data_dir``."""
    return model_path if model_path.is_absolute() else data_dir / model_path


def model_path_of(settings: Settings) -> Path:
    """The stage's model file: ``labelling.model_path``, relative paths under ``data_dir``."""
    return model_file(Path(settings.labelling.model_path), data_dir=settings.data_dir)


def check_recogniser(settings: Settings) -> None:
    """Load the model and CNN weights the stage would use; raise :class:`ObjectLabellingError` saying what is wrong."""
    load_recogniser(model_path_of(settings), settings.labelling.weights_path)
