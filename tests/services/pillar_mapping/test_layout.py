import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.cli import main
from services.pillar_mapping import (
    PillarMappingError,
    fit_racks,
    layout_features,
    read_landmarks_csv,
    write_landmarks_csv,
)
from services.pillar_mapping.synthetic import noisy_landmarks, rack_region
from shared.store import RevisionWrite


def test_fit_racks_writes_geojson_of_pillars_rows_and_bins(tmp_path: Path) -> None:
    layout = rack_region(aisles=2, bays=6)
    table, _ = noisy_landmarks(layout, np.random.default_rng(0))
    csv = tmp_path / "pillars.csv"
    write_landmarks_csv(csv, table[:, :2], table[:, [2, 3, 3, 4]].reshape(-1, 2, 2))
    result = fit_racks(csv, tmp_path / "out")
    collection = json.loads((tmp_path / "out" / "racks.geojson").read_text())
    kinds = {f["properties"]["kind"]: f["geometry"]["type"] for f in collection["features"]}
    assert kinds == {"pillar": "Point", "rack_row": "LineString", "bin": "Polygon"}
    rows = [f for f in collection["features"] if f["properties"]["kind"] == "rack_row"]
    assert {"n", "d", "theta", "x", "y"} <= rows[0]["properties"].keys()
    unseen = [f for f in collection["features"] if f["properties"].get("observed") is False]
    assert len(unseen) == len(layout.uprights) - len(table)
    assert len(result.bins) == len(layout.bin_centres)


def test_layout_features_fit_one_revision_write() -> None:
    table, _ = noisy_landmarks(rack_region(aisles=2, bays=5), np.random.default_rng(1))
    features = layout_features(fit_racks(table))
    write = RevisionWrite(stage="pillar_mapping", features=features)
    assert set(write.features) == {"pillar", "rack_row", "bin", "corridor"}
    assert all(len(v) > 0 for v in write.features.values())


def test_each_aisle_is_a_corridor_on_its_true_centre_line_holding_its_access_poses() -> None:
    hall = rack_region(aisles=3, bays=10, aisle_width_m=3.2)
    table, _ = noisy_landmarks(hall, np.random.default_rng(2))
    features = layout_features(fit_racks(table))

    corridors = {f.properties["aisle"]: f for f in features["corridor"]}

    assert len(corridors) == len(hall.aisles)
    for aisle, corridor in corridors.items():
        ring = np.asarray(corridor.geometry["coordinates"][0], dtype=np.float32)
        for item in (b for b in features["bin"] if b.properties["aisle"] == aisle):
            x, y, _ = item.properties["access_pose"]
            assert cv2.pointPolygonTest(ring.reshape(-1, 1, 2), (x, y), False) > 0
        centre = ring[:4].mean(axis=0)
        line = min(hall.aisles, key=lambda ends: _distance_to_line(centre, ends))
        assert _distance_to_line(centre, line) < 0.1
        assert abs(corridor.properties["width_m"] - 3.2) < 0.15


def _distance_to_line(point: np.ndarray, ends: np.ndarray) -> float:
    a, b = ends
    direction = (b - a) / np.linalg.norm(b - a)
    offset = point - a
    return float(abs(offset[0] * direction[1] - offset[1] * direction[0]))


def test_landmark_csv_round_trips(tmp_path: Path) -> None:
    means = np.array([[1.0, 2.0], [3.5, -4.25]])
    covs = np.array([[[1e-3, 2e-4], [2e-4, 3e-3]], [[4e-4, 0.0], [0.0, 4e-4]]])
    write_landmarks_csv(tmp_path / "p.csv", means, covs)
    table = read_landmarks_csv(tmp_path / "p.csv")
    assert np.allclose(table, [[1.0, 2.0, 1e-3, 2e-4, 3e-3], [3.5, -4.25, 4e-4, 0.0, 4e-4]])


def test_read_landmarks_csv_names_the_bad_line(tmp_path: Path) -> None:
    path = tmp_path / "p.csv"
    path.write_text("x,y,sxx,sxy,syy\n1,2,3\n")
    with pytest.raises(PillarMappingError, match=r"p.csv:2"):
        read_landmarks_csv(path)


def test_racks_fit_puts_bins_on_the_levels_given(tmp_path: Path) -> None:
    table, _ = noisy_landmarks(rack_region(aisles=1, bays=4), np.random.default_rng(3), missing_fraction=0.0)
    csv = tmp_path / "pillars.csv"
    write_landmarks_csv(csv, table[:, :2], table[:, [2, 3, 3, 4]].reshape(-1, 2, 2))

    assert main(["racks", "fit", str(csv), "--out", str(tmp_path / "out"), "--levels", "0,1.6,3.2"]) == 0
    bins = [f["properties"] for f in json.loads((tmp_path / "out" / "racks.geojson").read_text())["features"]
            if f["properties"]["kind"] == "bin"]
    assert {(b["level"], b["z_m"], b["id"][-3:]) for b in bins} == {(0, 0.0, "-01"), (1, 1.6, "-02"), (2, 3.2, "-03")}
    assert main(["racks", "fit", str(csv), "--out", str(tmp_path / "out"), "--levels", "0,3.2,1.6"]) == 1


def test_bin_confidence_falls_with_the_uncertainty_of_its_uprights_and_is_stored() -> None:
    hall = rack_region(aisles=2, bays=8)
    rng = np.random.default_rng(3)
    xy = hall.uprights + rng.normal(0.0, 0.01, hall.uprights.shape)
    sigma = np.full(len(xy), 0.01)
    vague = np.argmin(np.hypot(*(hall.uprights - hall.uprights.mean(axis=0)).T))  # one upright mid-hall
    sigma[vague] = 0.08
    table = np.column_stack([xy, sigma**2, np.zeros(len(xy)), sigma**2])

    layout = fit_racks(table)
    features = {f.key: f for f in layout_features(layout)["bin"]}

    confidence = np.array([b.confidence for b in layout.bins])
    assert np.all((confidence >= 0.0) & (confidence <= 1.0))
    corners = np.array([np.hypot(*(b.footprint - xy[vague]).T).min() < 0.05 for b in layout.bins])
    assert corners.any() and not corners.all()
    assert confidence[corners].max() < confidence[~corners].min()
    assert confidence[~corners].min() > 0.99
    assert all(features[b.id].confidence == b.confidence for b in layout.bins)


def test_bins_bounded_by_an_unseen_upright_get_less_confidence() -> None:
    hall = rack_region(aisles=2, bays=8)
    xy = hall.uprights + np.random.default_rng(4).normal(0.0, 0.01, hall.uprights.shape)
    unseen = np.argmin(np.hypot(*(hall.uprights - hall.uprights.mean(axis=0)).T))  # restored from its row's lattice
    table = np.delete(np.column_stack([xy, np.tile([1e-4, 0.0, 1e-4], (len(xy), 1))]), unseen, axis=0)

    layout = fit_racks(table)

    beside = np.array([np.hypot(*(b.footprint - hall.uprights[unseen]).T).min() < 0.05 for b in layout.bins])
    confidence = np.array([b.confidence for b in layout.bins])
    assert beside.any() and confidence[beside].max() <= 0.75
    assert confidence[~beside].min() > 0.99
