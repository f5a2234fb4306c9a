"""``aisle train-classifier`` / ``aisle eval-classifier`` and the demo's first-start model.

Real photos come from a data folder holding the two YOLO sets (``pallets/train``,
``forklift_person/train``, as in ``../shared/data/images``); the whole-image labels from the CSV
shipped in ``data/``. Simulator views add training samples (halls seeded from 1000) and give a
separate held-out figure (halls seeded from 2000, textured as the simulator textures its traffic).
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

from threadpoolctl import threadpool_limits

from services.labelling_training.datasets import Samples, YoloSet
from services.labelling_training.sim_training import sim_samples, simulated_views, training_textures
from services.labelling_training.training import (
    ROI_CLASSES,
    Evaluation,
    FeatureCache,
    evaluate_classifier,
    real_samples,
    train_classifier,
)
from services.object_labelling.classifier import LabelModel
from services.object_labelling.cnn import EfficientNetLite0, default_weights_path
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.retrieval import PriorDatabase
from services.simulator.cameras import photo_textures

log = logging.getLogger(__name__)

SCENE_LABELS = Path(__file__).with_name("data") / "scene_labels.csv"
VIEWS_PER_HALL = 20
TRAIN_HALLS = 1000
TEST_HALLS = 2000
QUICK_SIM_VIEWS = 60


def _real(data_dir: Path, *, test: bool, seed: int) -> Samples:
    missing = [d for d in ("pallets/train", "forklift_person/train") if not (data_dir / d / "images").is_dir()]
    if missing:
        raise ObjectLabellingError(f"{data_dir} lacks {missing}: expected the two YOLO photo sets there")
    sets = [YoloSet(data_dir / "pallets/train", {0: "pallet"}),
            YoloSet(data_dir / "forklift_person/train", {0: "forklift", 1: "human"})]
    return real_samples(sets, SCENE_LABELS, data_dir / "pallets/train/images", test=test, seed=seed)


def _halls(first: int, views: int) -> range:
    return range(first, first + -(-views // VIEWS_PER_HALL))


def train_from_sources(out: Path, *, data_dir: Path | None, sim_views: int, input_size_px: int = 128,
                       seed: int = 0, feature_cache: Path | None = None) -> LabelModel:
    """Train a model from the real photos under ``data_dir`` (training split) and/or ``sim_views`` renders.

    The renders are textured with crops of the training photos when there are any, else as the
    simulator textures its own traffic.
    """
    if data_dir is None and sim_views <= 0:
        raise ObjectLabellingError("nothing to train on: give a data folder or simulator views")
    weights = default_weights_path()
    net = EfficientNetLite0.load(weights)
    cache = FeatureCache(net, hashlib.sha256(weights.read_bytes()).hexdigest(), feature_cache)
    parts = []
    with threadpool_limits(limits=1, user_api="blas"):
        if data_dir is not None:
            parts.append(_real(data_dir, test=False, seed=seed))
        if sim_views > 0:
            textures = training_textures(parts[0].crops, seed=seed) if parts else photo_textures()
            log.info("rendering %d simulator views for training", sim_views)
            views = simulated_views(_halls(TRAIN_HALLS, sim_views), VIEWS_PER_HALL, textures=textures, seed=seed)
            parts.append(sim_samples(views, PriorDatabase.read_csv(), roi_classes=ROI_CLASSES,
                                     source_prefix="sim-train"))
        model = train_classifier(Samples.concat(parts), out, net=net, weights_sha256=cache.weights_sha256,
                                 input_size_px=input_size_px, cache=cache)
    cache.save()
    return model


def evaluate_from_sources(model_path: Path, *, data_dir: Path | None, sim_views: int, seed: int = 0,
                          feature_cache: Path | None = None) -> list[tuple[str, Evaluation]]:
    """Held-out figures: on the real photos' test split (if ``data_dir``) and on ``sim_views`` renders."""
    model = LabelModel.load(model_path)
    weights = default_weights_path()
    net = EfficientNetLite0.load(weights)
    cache = FeatureCache(net, hashlib.sha256(weights.read_bytes()).hexdigest(), feature_cache)
    results = []
    with threadpool_limits(limits=1, user_api="blas"):
        if data_dir is not None:
            results.append((f"real photos, held-out sources (split seed {seed})",
                            evaluate_classifier(model, _real(data_dir, test=True, seed=seed), cache=cache)))
        if sim_views > 0:
            views = simulated_views(_halls(TEST_HALLS, sim_views), VIEWS_PER_HALL, textures=photo_textures(),
                                    seed=seed + 1)
            samples = sim_samples(views, PriorDatabase.read_csv(), roi_classes=ROI_CLASSES, source_prefix="sim-test")
            results.append((f"simulator renders of unseen halls ({sim_views} views)",
                            evaluate_classifier(model, samples, cache=cache)))
    cache.save()
    return results


def ensure_demo_model(path: Path) -> None:
    """Train a quick model from simulator renders at ``path`` if there is no file there yet."""
    if path.exists():
        return
    log.warning("no classifier model at %s: training a quick one from %d simulator views (a minute or two, once)",
                path, QUICK_SIM_VIEWS)
    train_from_sources(path, data_dir=None, sim_views=QUICK_SIM_VIEWS)
