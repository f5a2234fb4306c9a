"""A decomposition as store records: layers, features and topology in map metres."""

from __future__ import annotations

import dataclasses
import math
from functools import cache

import numpy as np
import pytest

from services.grid_decomposition import (
    PLACE_LABELS,
    Connection,
    Decomposition,
    DecompositionError,
    decompose,
    decomposition_features,
    decomposition_layers,
    decomposition_topology,
)
from shared.store import FEATURE_KINDS, RevisionWrite
from shared.vocabulary import PlaceLabel
from tests.services.grid_decomposition.warehouse import Warehouse, synthetic_warehouse

RES_M = 0.1
"""Seeds 0 and 3 give labelled warehouses at 0.1 m; others collapse to one region in the core (reported)."""
ORIGIN_XY_M = (-3.0, 2.0)
REGION_KINDS = {"corridor", "junction", "room", "open_area", "region"}


@cache
def _warehouse(seed: int) -> tuple[Warehouse, Decomposition]:
    house = synthetic_warehouse(seed, resolution_m=RES_M)
    return house, decompose(house.occupancy, resolution_m=RES_M, origin_xy_m=ORIGIN_XY_M)


def _cell(x_m: float, y_m: float) -> tuple[int, int]:
    """(row, col) of the cell holding a point (row 0 = lowest y)."""
    return math.floor((y_m - ORIGIN_XY_M[1]) / RES_M), math.floor((x_m - ORIGIN_XY_M[0]) / RES_M)


@pytest.mark.parametrize("seed", [0, 3])
def test_region_outlines_lie_on_their_own_region_cells(seed: int) -> None:
    _, result = _warehouse(seed)
    features = decomposition_features(result)
    regions = [f for kind in REGION_KINDS for f in features[kind]]
    assert regions
    for feature in regions:
        for polygon in feature.geometry["coordinates"]:
            for ring in polygon:
                cells = np.array([_cell(x, y) for x, y in ring])
                assert np.all(result.segments[cells[:, 0], cells[:, 1]] == feature.properties["region_id"])


@pytest.mark.parametrize("seed", [0, 3])
def test_features_form_a_valid_revision_of_known_kinds(seed: int) -> None:
    house, result = _warehouse(seed)
    features = decomposition_features(result)
    assert set(features) <= FEATURE_KINDS
    RevisionWrite("grid_decomposition", features=features)  # unique keys, one kind per list
    height, width = np.array(house.occupancy.shape) * RES_M
    for feature in (f for items in features.values() for f in items):
        points = np.array(_points(feature.geometry["coordinates"]))
        assert np.all(points[:, 0] >= ORIGIN_XY_M[0]) and np.all(points[:, 0] <= ORIGIN_XY_M[0] + width)
        assert np.all(points[:, 1] >= ORIGIN_XY_M[1]) and np.all(points[:, 1] <= ORIGIN_XY_M[1] + height)


def _points(coordinates: object) -> list[tuple[float, float]]:
    if isinstance(coordinates, list) and len(coordinates) == 2 and all(isinstance(c, float) for c in coordinates):
        return [(coordinates[0], coordinates[1])]
    assert isinstance(coordinates, list)
    return [p for item in coordinates for p in _points(item)]


def test_storage_regions_are_region_features_labelled_storage() -> None:
    _, result = _warehouse(0)
    features = decomposition_features(result)
    storage = [r.region_id for r in result.regions.values() if r.label is PlaceLabel.STORAGE]
    assert storage, "the synthetic warehouse should show pallet cells"
    by_id = {f.properties["region_id"]: f for f in features["region"]}
    assert all(by_id[rid].properties["label"] == "storage" for rid in storage)
    assert {f.properties["label"] for f in features["corridor"]} == {"corridor"}


def test_topology_nodes_are_the_region_features() -> None:
    _, result = _warehouse(0)
    features = decomposition_features(result)
    nodes, edges = decomposition_topology(result)
    region_features = {f.key: f for kind in REGION_KINDS for f in features[kind]}
    assert {n.key for n in nodes} == set(region_features)
    for node in nodes:
        assert node.attributes["feature_kind"] == region_features[node.key].kind
        assert node.kind == region_features[node.key].properties["label"]
    keys = {n.key for n in nodes}
    assert edges and all(e.source in keys and e.target in keys for e in edges)
    assert {e.attributes["connection"] for e in edges} <= {c.value for c in Connection}


def test_layers_carry_labels_and_segments_in_grid_order() -> None:
    house, result = _warehouse(0)
    labels, segments = decomposition_layers(result, meta={"source_revision": 7})
    assert labels.data.dtype == np.uint8 and segments.data.dtype == np.uint16
    assert labels.data.shape == segments.data.shape == house.occupancy.shape
    assert (labels.origin_x_m, labels.origin_y_m, labels.resolution_m) == (*ORIGIN_XY_M, RES_M)
    assert labels.meta["encoding"] == PLACE_LABELS
    assert labels.meta["classes"][PlaceLabel.JUNCTION] == "junction"
    assert labels.meta["source_revision"] == segments.meta["source_revision"] == 7
    free = (house.occupancy >= 0) & (house.occupancy < 25)
    assert not np.any((labels.data > 0) & ~free)
    np.testing.assert_array_equal(segments.data, result.segments)


def test_layers_widen_the_segment_layer_for_ids_beyond_uint16() -> None:
    _, result = _warehouse(0)
    crowded = dataclasses.replace(result, segments=np.where(result.segments > 0, result.segments + 70_000, 0))
    _, segments = decomposition_layers(crowded)
    assert segments.data.dtype == np.uint32
    np.testing.assert_array_equal(segments.data, crowded.segments)


def test_layers_reject_negative_region_ids() -> None:
    _, result = _warehouse(0)
    broken = dataclasses.replace(result, segments=np.full_like(result.segments, -1))
    with pytest.raises(DecompositionError, match="negative"):
        decomposition_layers(broken)
