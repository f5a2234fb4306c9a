"""Simulated RGB-D views with ground truth, and how many of the objects in them segmentation finds."""

from __future__ import annotations

import numpy as np
import pytest

from services.labelling_training.matching import match_boxes, score_segmentation
from services.labelling_training.sim_views import SimView, sample_views, scatter_hall
from services.object_labelling import PriorDatabase
from services.object_labelling.crops import box_iou


@pytest.fixture(scope="module")
def views() -> list[SimView]:
    """18 views of three scatter halls (seeds not used anywhere else), procedural textures (about 10 s)."""
    rng = np.random.default_rng(5)
    return [view for hall in (71, 72, 73) for view in sample_views(scatter_hall(hall), rng, 6)]


@pytest.mark.slow
def test_ground_truth_boxes_hold_the_pixels_of_their_actor(views: list[SimView]) -> None:
    assert sum(len(v.objects) for v in views) >= 10
    for view in views:
        assert view.depth_mm.shape == view.rgb.shape[:2] == (480, 640) and view.depth_mm.any()
        for obj in view.objects:
            r0, c0, r1, c1 = obj.box
            inside = view.actor_pixels[r0 : r1 + 1, c0 : c1 + 1]
            assert (inside >= 0).any()
            assert 0.5 <= obj.visible_fraction <= 1.0
            ids = np.unique(inside[inside >= 0])
            assert obj.label in {view.actor_labels[i] for i in ids}


def test_box_matching_is_one_to_one_and_needs_half_overlap() -> None:
    truth = [(0, 0, 99, 99), (0, 200, 99, 299)]
    found = [(0, 0, 99, 79), (0, 0, 99, 99), (0, 260, 99, 359)]
    assert box_iou(np.array(truth[:1]), np.array(found[:1]))[0, 0] == pytest.approx(0.8)
    assert match_boxes(truth, found) == [(0, 1, 1.0)]  # the second truth box overlaps only 40/160


@pytest.mark.slow
def test_segmentation_finds_at_least_90_percent_of_the_objects_in_simulated_frames(views: list[SimView]) -> None:
    score = score_segmentation(views, PriorDatabase.read_csv())
    print(f"objects {score.objects} found {score.found} recall {score.recall:.3f}")
    assert sum(score.objects.values()) >= 10
    assert score.recall >= 0.9
