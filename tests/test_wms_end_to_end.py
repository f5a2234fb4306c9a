"""A simulated warehouse played through the whole stack, then asked what a WMS asks, through the API only.

One robot with a fisheye camera surveys the demo warehouse into a rosbag2; ``aisle run --replay`` maps it
(occupancy, grid decomposition, pillar mapping); an operator registers the docks; then the WMS asks where
a bin is, how to drive from it to a dock, what is at a point, and takes the LIF export.
"""

from __future__ import annotations

import itertools
import json
import math
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import httpx2 as httpx
import jsonschema
import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from skimage.graph import route_through_array

from services.simulator import load_world, sim_run
from shared.mapfiles import MapImage, read_map_yaml
from tests.helpers import data_path, wait_for
from tests.stack import POLL_S, aisle_run, health

pytestmark = pytest.mark.slow

MAP = "/v1/maps/site"
BIN_X = "02-005-01"
"""Bin X in the site's own numbering (aisle-bay-level), which the WMS imports with surveyed positions; if the
survey did not map it, the mapped bin of its aisle nearest to it."""
AISLE = 2
SURVEY_NOISE_M = 0.15
DOCK = "G1"
FISHEYE_HZ = 2.0
REPLAY_RATE = "2"


def _truth(truth_dir: Path) -> dict[str, list[dict[str, Any]]]:
    collection = json.loads((truth_dir / "world.geojson").read_text())
    out: dict[str, list[dict[str, Any]]] = {}
    for feature in collection["features"]:
        out.setdefault(feature["properties"]["kind"], []).append(feature)
    return out


def _ring_centre(feature: dict[str, Any]) -> np.ndarray:
    ring = np.asarray(feature["geometry"]["coordinates"][0][:-1], dtype=float)
    centre: np.ndarray = ring.mean(axis=0)
    return centre


def _inside(point: np.ndarray, feature: dict[str, Any], margin_m: float = 0.0) -> bool:
    """Whether ``point`` lies in the bounding box of a Polygon feature, grown by ``margin_m``."""
    ring = np.asarray(feature["geometry"]["coordinates"][0], dtype=float)
    return bool(ring[:, 0].min() - margin_m <= point[0] <= ring[:, 0].max() + margin_m
                and ring[:, 1].min() - margin_m <= point[1] <= ring[:, 1].max() + margin_m)


@pytest.fixture(scope="module")
def survey(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo warehouse surveyed by one robot with a fisheye camera: a rosbag2 with its ground truth beside."""
    bag = tmp_path_factory.mktemp("survey") / "bag"
    sim_run(load_world("demo"), bag, robots=1, cameras=["fisheye"], fisheye_rate_hz=FISHEYE_HZ)
    return bag


@pytest.fixture(scope="module")
def answers(survey: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Replay the survey through ``aisle run``, then ask the API; every answer by name."""
    tmp_path = tmp_path_factory.mktemp("stack")
    truth = _truth(Path(f"{survey}.truth"))
    out: dict[str, Any] = {}
    with aisle_run(tmp_path, "--replay", str(survey), "--rate", REPLAY_RATE) as client:
        admin = _first_admin_key(tmp_path / "aisle.log")
        frames = _frames(survey)
        wait_for(lambda: _frames_handled(client) >= 0.95 * frames, timeout_s=300, interval_s=POLL_S,
                 what="the pillar stage to have taken in the survey's fisheye frames")
        wait_for(lambda: _decomposed_after_survey(client), timeout_s=120, interval_s=POLL_S,
                 what="a decomposition of the survey")
        wait_for(_settled(client), timeout_s=120, interval_s=POLL_S, what="the bins to stop changing")
        out["places"] = [_put_dock(client, admin, dock) for dock in truth["dock"]]
        out["import"] = client.put(f"{MAP}/wms-bins", json=_site_bin_list(truth), headers={"X-API-Key": admin})
        matched = [m["wms_id"] for m in out["import"].json().get("matched", [])]
        out["x"] = _bin_x(matched)
        out["bin"] = client.get(f"{MAP}/bins/{out['x']}").json()
        out["route"] = client.get(f"{MAP}/routes", params={"from": f"bin:{out['x']}", "to": f"dock:{DOCK}"})
        if out["bin"].get("corridor"):
            out["corridor"] = client.get(f"{MAP}/features/corridor/{out['bin']['corridor']['key']}").json()
        aisle_corridor = next(c for c in truth["corridor"] if c["properties"].get("aisle") == AISLE)
        out["point_in_aisle"] = _ring_centre(aisle_corridor)
        out["semantics_aisle"] = client.get(f"{MAP}/semantics", params=dict(zip("xy", out["point_in_aisle"],
                                                                                  strict=True))).json()
        out["lif"] = client.get(f"{MAP}/exports/lif")
        out["occupancy_meta"] = client.get(f"{MAP}/layers/occupancy").json()
    return out


def _settled(client: httpx.Client, quiet_s: float = 5.0) -> Callable[[], bool]:
    """A condition: the bin list has not changed for ``quiet_s`` (the pillar stage has taken in the survey)."""
    seen: dict[str, Any] = {"bins": None, "since": time.monotonic()}

    def check() -> bool:
        bins = client.get(f"{MAP}/bins", params={"limit": 1000}).json()["bins"]
        now = [(b["detected_id"], b["revision_id"]) for b in bins]
        if now != seen["bins"]:
            seen.update(bins=now, since=time.monotonic())
        return bool(now) and time.monotonic() - seen["since"] >= quiet_s

    return check


def _bin_x(matched: list[str]) -> str:
    """Bin X: 02-005-01 if it was matched, else the matched floor bin of aisle 02 nearest bay 5."""
    aisle = [wms_id for wms_id in matched if wms_id.startswith(f"{AISLE:02d}-")]
    assert aisle, f"no bin of aisle {AISLE} matched: {matched}"
    return min(aisle, key=lambda wms_id: (wms_id != BIN_X, abs(int(wms_id.split("-")[1]) - 5)))


def _site_bin_list(truth: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """The WMS's floor-level bins with their ids and positions surveyed to about 15 cm."""
    rng = np.random.default_rng(7)
    bins = [{"id": b["properties"]["id"], "level": 0, "x_m": float(c[0]), "y_m": float(c[1])}
            for b in truth["bin"] if b["properties"]["level"] == 1
            for c in [_ring_centre(b) + rng.normal(0.0, SURVEY_NOISE_M / 2, 2)]]
    return {"bins": bins, "tolerance_m": 0.6}


def _first_admin_key(log: Path) -> str:
    found = re.search(r"FIRST ADMIN API KEY.*\n#\s+#\n#\s+(\S+)\s+#\n", log.read_text())  # in its box
    assert found, "aisle run printed no first admin key"
    return found.group(1)


def _frames(bag: Path) -> int:
    with Reader(bag) as reader:
        return sum(c.msgcount for c in reader.connections if c.topic.endswith("/fisheye/image_raw"))


FRAME_OUTCOMES = ("frames", "frames_superseded", "bad_frames", "frames_without_camera_info", "frames_without_pose",
                  "frames_without_odometry", "fisheye/image_raw.dropped")
"""What becomes of a fisheye frame in the pillar stage: mapped, or (on a machine too busy to keep up) replaced by a
newer one of its robot or dropped from the full queue, or refused; each counted."""


def _frames_handled(client: httpx.Client) -> int:
    """Fisheye frames the pillar stage has done with, whatever became of them (a busy machine maps fewer of them:
    waiting for a count of frames mapped would wait on the machine's speed, not on the survey)."""
    counters: dict[str, int] = next((w["counters"] for w in health(client)["workers"] if w["name"] == "pillar_mapping"),
                                    {})
    return sum(int(counters.get(f"pillar_mapping.{outcome}", 0)) for outcome in FRAME_OUTCOMES)


def _decomposed_after_survey(client: httpx.Client) -> bool:
    revisions = client.get(f"{MAP}/revisions", params={"limit": 1000}).json()["revisions"]
    while len(revisions) == 1000:
        more = client.get(f"{MAP}/revisions", params={"after": revisions[-1]["id"], "limit": 1000}).json()
        revisions += more["revisions"]
    occupancy = [r["id"] for r in revisions if r["stage"] == "occupancy_mapping"]
    decompositions = [r for r in revisions if r["stage"] == "grid_decomposition"]
    return bool(occupancy and decompositions
                and decompositions[-1]["summary"]["source_revision"] >= occupancy[len(occupancy) * 9 // 10])


def _put_dock(client: httpx.Client, key: str, dock: dict[str, Any]) -> dict[str, Any]:
    """Register a dock as an operator would: its door on the wall, and an approach point 2 m inside."""
    (x0, y0), (x1, y1) = dock["geometry"]["coordinates"][:2]
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    inward = np.array([-(y1 - y0), x1 - x0]) / math.hypot(x1 - x0, y1 - y0)
    if (np.array([20.0, 12.5]) - centre) @ inward < 0:  # point into the hall
        inward = -inward
    approach = centre + 2.0 * inward
    body = {"geometry": {"type": "Point", "coordinates": centre.tolist()},
            "approach_pose": {"x_m": approach[0], "y_m": approach[1],
                              "yaw_rad": math.atan2(-inward[1], -inward[0])},
            "name": f"Dock {dock['properties']['id']}"}
    response = client.put(f"{MAP}/places/dock/{dock['properties']['id']}", json=body, headers={"X-API-Key": key})
    assert response.status_code in (200, 201), response.text
    return dict(response.json())


def _racks(truth: dict[str, list[dict[str, Any]]], grid: MapImage) -> np.ndarray:
    """The true racks' footprints on ``grid`` (no vehicle drives under a rack, though a lidar sees through an
    empty bay), less the cross aisles that cut through them."""
    def cells(feature: dict[str, Any]) -> np.ndarray:
        ring = np.asarray(feature["geometry"]["coordinates"][0], dtype=float)
        return np.round((ring - (grid.origin_x_m, grid.origin_y_m)) / grid.resolution_m - 0.5).astype(np.int32)

    racks = np.zeros(grid.occupancy.shape, np.uint8)
    cv2.fillPoly(racks, [cells(f) for f in truth["rack_row"]], 1)
    cv2.fillPoly(racks, [cells(f) for f in truth["corridor"] if f["properties"].get("corridor_kind") == "cross_aisle"],
                 0)
    return racks.astype(bool)


def test_where_is_bin_x(answers: dict[str, Any], survey: Path) -> None:
    truth = _truth(Path(f"{survey}.truth"))
    bin_x = answers["x"]
    true_bin = next(b for b in truth["bin"] if b["properties"]["id"] == bin_x)
    imported = answers["import"]
    assert imported.status_code == 200, imported.text
    counts = imported.json()["counts"]
    assert counts["matched"] >= 0.5 * (counts["matched"] + counts["missing_in_map"]), counts  # most are found

    found = answers["bin"]

    assert found.get("id") == bin_x and found["status"] == "matched", found
    error = np.hypot(*(np.asarray(found["centre"]) - _ring_centre(true_bin)))
    assert error <= 0.10, f"bin {bin_x} (Aisle's {found['detected_id']}) is {error:.3f} m from its true centre"
    aisle = next(c for c in truth["corridor"] if c["properties"].get("aisle") == AISLE)
    middle = np.asarray(aisle["properties"]["start"]) / 2 + np.asarray(aisle["properties"]["end"]) / 2
    assert _inside(middle, answers["corridor"]), "the bin's corridor is not its true aisle"


def test_route_from_bin_x_to_the_dock_is_drivable_through_its_aisle(answers: dict[str, Any], survey: Path) -> None:
    truth_dir = Path(f"{survey}.truth")
    truth = _truth(truth_dir)
    grid = read_map_yaml(truth_dir / "occupancy.yaml")
    free = (grid.occupancy >= 0) & (grid.occupancy < 50) & ~_racks(truth, grid)
    response = answers["route"]
    assert response.status_code == 200, response.text
    route = response.json()
    points = np.array([[w["x_m"], w["y_m"]] for w in route["waypoints"]])

    cells = []
    for a, b in itertools.pairwise(points):
        steps = max(2, math.ceil(np.hypot(*(b - a)) / (grid.resolution_m / 2)))
        cells.append(a + np.linspace(0.0, 1.0, steps)[:, None] * (b - a))
    samples = np.vstack(cells)
    rows = np.floor((samples[:, 1] - grid.origin_y_m) / grid.resolution_m).astype(int)
    cols = np.floor((samples[:, 0] - grid.origin_x_m) / grid.resolution_m).astype(int)
    assert free[rows, cols].all(), "the route crosses an obstacle or a rack of the true map"

    aisle = next(c for c in truth["corridor"] if c["properties"].get("aisle") == AISLE)
    assert _inside(points[0], aisle, margin_m=0.3), "the route does not start in the bin's aisle"
    assert route["corridors"][0] == answers["bin"]["corridor"]["key"], route["corridors"]
    assert {r["kind"] for r in route["regions"]} <= {"corridor", "junction", "room", "open_area"}
    dock = next(d for d in answers["places"] if d["key"] == DOCK)
    assert np.hypot(*(points[-1] - np.asarray(dock["target"]))) < 0.5

    def cell(xy: np.ndarray) -> tuple[int, int]:
        return (int((xy[1] - grid.origin_y_m) / grid.resolution_m), int((xy[0] - grid.origin_x_m) / grid.resolution_m))

    cost = np.where(free, 1.0, 1e9)  # obstacles all but impassable
    _, shortest = route_through_array(cost, cell(points[0]), cell(points[-1]),  # type: ignore[no-untyped-call]
                                      fully_connected=True, geometric=True)
    assert route["length_m"] <= 1.3 * shortest * grid.resolution_m + 1.0, "the route is far from the shortest"


def test_what_is_in_the_middle_of_an_aisle(answers: dict[str, Any]) -> None:
    found = answers["semantics_aisle"]

    assert found["occupancy"] is not None and 0 <= found["occupancy"] < 50
    assert found["place"] is not None and found["place"]["label"] == "corridor"


def test_lif_export_validates_against_the_vdma_schema(answers: dict[str, Any]) -> None:
    schema_path = data_path("schemas", "LIF.schema.json")
    response = answers["lif"]
    assert response.status_code == 200, response.text
    document = response.json()

    jsonschema.validate(document, json.loads(schema_path.read_text()))
    layout = document["layouts"][0]
    assert layout["nodes"] and layout["edges"] and layout["stations"]
