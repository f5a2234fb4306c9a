from __future__ import annotations

import numpy as np
import pytest

from services.object_labelling import (
    ObjectLabellingError,
    PriorDatabase,
    Segment,
    border_weights,
    range_height_scan,
    retrieve,
    segments,
)
from tests.services.object_labelling.synthetic import render_depth, true_plane, vga_intrinsics

INTRINSICS = vga_intrinsics()


def _segment(
    width_m: float, height_m: float, *, box: tuple[int, int, int, int] = (200, 200, 400, 300), range_m: float = 3.0
) -> Segment:
    return Segment(0, 10, width_m, height_m, range_m, 0.0, box)


@pytest.mark.parametrize(
    ("width_m", "height_m", "label"),
    [
        (1.18, 0.15, "pallet"),
        (0.82, 0.14, "pallet"),
        (1.2, 1.25, "pallet"),  # with its load
        (0.5, 1.72, "human"),
        (2.5, 2.15, "forklift"),
    ],
)
def test_retrieve_names_the_class_of_typical_dimensions(width_m: float, height_m: float, label: str) -> None:
    [proposal] = retrieve([_segment(width_m, height_m)], PriorDatabase.read_csv(), INTRINSICS)
    assert proposal.label == label


def test_retrieve_leaves_implausible_dimensions_unlabelled() -> None:
    [proposal] = retrieve([_segment(6.0, 0.7)], PriorDatabase.read_csv(), INTRINSICS)
    assert proposal.label is None and proposal.distances == {}


def test_a_segment_cut_by_the_image_top_may_be_shorter_than_its_class() -> None:
    database = PriorDatabase.read_csv()
    inside = retrieve([_segment(0.5, 1.2, box=(100, 300, 400, 360))], database, INTRINSICS)[0]
    cut = retrieve([_segment(0.5, 1.2, box=(0, 300, 400, 360))], database, INTRINSICS)[0]
    assert "human" not in inside.distances
    assert cut.label == "human"


def test_border_weights_fall_from_one_at_the_border() -> None:
    lut = border_weights(640, sigma_px=31.05)
    assert lut[0] == 1.0 and (np.diff(lut) < 0).all() and lut[200] < 1e-6


def test_kd_tree_gate_agrees_with_brute_force_mahalanobis() -> None:
    rng = np.random.default_rng(0)
    database = PriorDatabase.from_rows([("a" if i % 2 else "b", *rng.uniform(0.1, 3.0, 2)) for i in range(60)])
    queries = [_segment(*rng.uniform(0.1, 3.0, 2), range_m=float(rng.uniform(0.5, 5))) for _ in range(50)]
    for proposal in retrieve(queries, database, INTRINSICS, occlusion_width_m=0.3, occlusion_height_m=0.1):
        query = np.array([proposal.segment.width_m, proposal.segment.height_m])
        sigma = np.array([0.3, 0.1]) + 0.01 * proposal.segment.range_m
        d = np.sqrt((((database.dimensions - query) / sigma) ** 2).sum(axis=1))
        for name in ("a", "b"):
            mask = np.array(database.classes) == name
            best = d[mask].min()
            assert proposal.distances.get(name, np.inf) == (pytest.approx(best) if best <= 3.0 else np.inf)


def test_retrieval_labels_a_rendered_pallet_and_person() -> None:
    plane = true_plane(1.0, 0.25)
    # a EUR pallet side-on, and a person-sized box whose head the image top cuts off
    scene = [(2.6, 0.7, 0.8, 1.2, 0.144), (3.0, -0.6, 0.3, 0.5, 1.75)]
    found = segments(range_height_scan(render_depth(INTRINSICS, scene, noise_m=0.005), INTRINSICS, plane))
    proposals = retrieve(found, PriorDatabase.read_csv(), INTRINSICS)
    assert sorted(str(p.label) for p in proposals) == ["human", "pallet"]


def test_prior_database_rejects_bad_dimensions() -> None:
    with pytest.raises(ObjectLabellingError, match="positive"):
        PriorDatabase.from_rows([("pallet", -1.0, 0.1)])
