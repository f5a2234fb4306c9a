from __future__ import annotations

import numpy as np
import pytest

from services.object_labelling import (
    UNKNOWN,
    EfficientNetLite0,
    ObjectLabeller,
    ObjectLabellingError,
    PriorDatabase,
)
from tests.services.object_labelling.synthetic import render_depth, true_plane, vga_intrinsics
from tests.services.object_labelling.test_classifier import random_model

SCENE = [(2.6, 0.7, 0.8, 1.2, 0.144), (3.0, -0.6, 0.3, 0.5, 1.75), (4.2, 0.0, 0.3, 0.3, 0.7)]
"""A pallet, a person and, behind them, something the size of a partly hidden loaded pallet."""


@pytest.fixture(scope="module")
def scene_depth() -> np.ndarray:
    return render_depth(vga_intrinsics(), SCENE, noise_m=0.005)


@pytest.fixture(scope="module")
def empty_depth() -> np.ndarray:
    return render_depth(vga_intrinsics(), [])


def _labeller(
    net: EfficientNetLite0, *, max_rois: int = 3, roi_reuse_frames: int = 10, scene_period_frames: int = 1
) -> ObjectLabeller:
    return ObjectLabeller(
        net,
        random_model(input_size_px=64),
        PriorDatabase.read_csv(),
        vga_intrinsics(),
        true_plane(1.0, 0.25),
        max_rois=max_rois,
        roi_reuse_frames=roi_reuse_frames,
        scene_period_frames=scene_period_frames,
    )


def _rgb(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (480, 640, 3), dtype=np.uint8)


def test_label_runs_the_whole_chain_on_a_rendered_frame(net: EfficientNetLite0, scene_depth: np.ndarray) -> None:
    labeller = _labeller(net)
    result = labeller.label(_rgb(), scene_depth)
    assert result.ground.valid
    assert sorted(str(p.label) for p in result.proposals) == ["human", "pallet", "pallet"]
    assert len(result.objects) == 3
    classes = (*labeller.model.roi.classes, UNKNOWN)
    for obj in result.objects:
        assert obj.label in classes
        assert obj.label == UNKNOWN or obj.label in obj.proposal.distances  # the size prior allows it
    assert set(result.scene) == {"rack", "gate"}
    assert set(result.timings_s) >= {"range_scan", "roi_cnn_svm", "scene_cnn_svm"}


def test_label_keeps_only_the_closest_rois(net: EfficientNetLite0, scene_depth: np.ndarray) -> None:
    result = _labeller(net, max_rois=1).label(_rgb(), scene_depth)
    [only] = result.objects
    assert only.proposal.segment.range_m == min(p.segment.range_m for p in result.proposals if p.label)


@pytest.fixture
def cnn_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Batch sizes of every CNN call from now on."""
    calls: list[int] = []
    features = EfficientNetLite0.features

    def counting(self: EfficientNetLite0, images: np.ndarray) -> np.ndarray:
        calls.append(images.shape[0])
        return features(self, images)

    monkeypatch.setattr(EfficientNetLite0, "features", counting)
    return calls


def test_label_reuses_the_scene_class_while_the_image_is_unchanged(
    net: EfficientNetLite0, empty_depth: np.ndarray, cnn_calls: list[int]
) -> None:
    labeller = _labeller(net)  # an empty floor has no ROIs: every CNN call is for the whole image
    labeller.label(_rgb(0), empty_depth)
    labeller.label(_rgb(0), empty_depth)
    assert len(cnn_calls) == 1
    labeller.label(np.zeros((480, 640, 3), np.uint8), empty_depth)
    assert len(cnn_calls) == 2


def test_label_classifies_the_whole_image_at_most_every_few_frames(
    net: EfficientNetLite0, empty_depth: np.ndarray, cnn_calls: list[int]
) -> None:
    labeller = _labeller(net, scene_period_frames=3)
    black, grey = np.zeros((480, 640, 3), np.uint8), np.full((480, 640, 3), 128, np.uint8)
    for image in (black, grey, grey, grey, black):
        labeller.label(image, empty_depth)
    assert len(cnn_calls) == 2  # black; grey only from the third frame on; black again too soon


def test_label_reuses_roi_classes_only_while_the_rois_look_the_same(
    net: EfficientNetLite0, scene_depth: np.ndarray
) -> None:
    labeller = _labeller(net, roi_reuse_frames=2)
    first = labeller.label(_rgb(0), scene_depth)
    assert first.cnn_rois == len(first.objects) == 3
    again = labeller.label(_rgb(0), scene_depth)
    assert again.cnn_rois == 0
    assert [(o.label, o.probability) for o in again.objects] == [(o.label, o.probability) for o in first.objects]
    assert labeller.label(_rgb(0), scene_depth).cnn_rois == 0
    assert labeller.label(_rgb(0), scene_depth).cnn_rois == 3  # reused twice: the CNN looks again
    assert labeller.label(np.zeros((480, 640, 3), np.uint8), scene_depth).cnn_rois == 3  # the ROIs look different


def test_label_classifies_every_roi_every_frame_without_reuse(net: EfficientNetLite0, scene_depth: np.ndarray) -> None:
    labeller = _labeller(net, roi_reuse_frames=0)
    assert [labeller.label(_rgb(0), scene_depth).cnn_rois for _ in range(3)] == [3, 3, 3]


def test_label_flags_a_moved_camera(net: EfficientNetLite0) -> None:
    result = _labeller(net).label(_rgb(), render_depth(vga_intrinsics(), [], pitch_rad=0.45))
    assert not result.ground.valid


def test_label_rejects_corrupt_frames(net: EfficientNetLite0, empty_depth: np.ndarray) -> None:
    labeller = _labeller(net)
    depth = empty_depth
    with pytest.raises(ObjectLabellingError, match="colour image is 320x240 px but depth is 640x480 px"):
        labeller.label(_rgb()[:240, :320], depth)
    with pytest.raises(ObjectLabellingError, match="holds no depth"):
        labeller.label(_rgb(), np.zeros_like(depth))
    with pytest.raises(ObjectLabellingError, match="uint8 RGB"):
        labeller.label(_rgb().astype(np.float32), depth)
    with pytest.raises(ObjectLabellingError, match="uint16"):
        labeller.label(_rgb(), depth.astype(np.int32))
