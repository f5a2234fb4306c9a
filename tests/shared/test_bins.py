"""The bin record: what the pillar stage writes is what everyone reads back."""

from __future__ import annotations

import json

import numpy as np
import pytest

from services.pillar_mapping import fit_racks, layout_features
from services.pillar_mapping.synthetic import noisy_landmarks, rack_region
from shared.bins import AccessPose, Bin, BinError, Opening
from shared.store import Feature

RING = ((0.0, 0.0), (1.2, 0.0), (1.2, 1.0), (0.0, 1.0), (0.0, 0.0))


def test_a_bin_reads_back_as_it_was_written() -> None:
    record = Bin(id="03-014", centre=(0.6, 0.5), aisle=3, bay=14, level=1, z_m=1.6, footprint=RING,
                 access_pose=AccessPose(0.6, -1.0, 1.5708), row="r0-006", back_row="r0-007", confidence=0.9)
    assert Bin.from_feature(record.feature()) == record


def test_the_pillar_stage_writes_bins_every_reader_can_read() -> None:
    table, _ = noisy_landmarks(rack_region(aisles=2, bays=5), np.random.default_rng(1))
    for feature in layout_features(fit_racks(table))["bin"]:
        record = Bin.from_feature(feature)
        again = record.feature()
        assert record.id == feature.key and record.aisle is not None and record.access_pose is not None
        assert json.dumps(again.properties) == json.dumps(feature.properties)
        assert json.dumps(again.geometry) == json.dumps(feature.geometry)


def test_the_opening_is_the_front_edge_of_the_footprint() -> None:
    record = Bin(id="B1", centre=(0.6, 0.5), footprint=RING)
    assert record.opening == Opening((0.0, 0.0), (1.2, 0.0), 1.2)
    assert Bin(id="B2", centre=(0.0, 0.0)).opening is None


def test_missing_or_mistyped_properties_read_as_none() -> None:
    feature = Feature("bin", "B1", {"type": "Point", "coordinates": [2.0, 1.0]},
                      {"aisle": "3", "level": True, "access_pose": [1, 2], "row": 7})
    record = Bin.from_feature(feature)
    assert record == Bin(id="B1", centre=(2.0, 1.0))
    assert record.reach == (2.0, 1.0)


def test_reading_a_feature_of_another_kind_is_an_error() -> None:
    with pytest.raises(BinError, match="dock/G1 is not a bin"):
        Bin.from_feature(Feature("dock", "G1", {"type": "Point", "coordinates": [0.0, 0.0]}))


def test_a_bin_the_store_would_refuse_is_an_error() -> None:
    with pytest.raises(BinError, match="bin 'B1'"):
        Bin(id="B1", centre=(float("nan"), 0.0)).feature()
    with pytest.raises(BinError, match="needs an id"):
        Bin(id="", centre=(0.0, 0.0))
