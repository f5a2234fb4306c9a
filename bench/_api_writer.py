"""The stage side of ``bench_api_load.py``, run in its own process: writes the simulated hall into a map store,
then keeps writing revisions as the occupancy and pillar-mapping stages do until told to stop.

Protocol on stdin/stdout, one line each: the writer stores the whole hall (occupancy, places, walls, docks,
chargers, rack rows, uprights and bins), then prints ``ready <n bins>``; the bench writes ``go``, and the
writer alternates, every ``--period-s``, an occupancy revision (the hall's 5 cm occupancy layer with a
patch changed) and a pillar-mapping revision (every rack row, upright and bin, 1 % of the bins nudged by a
centimetre); on ``stop`` it prints a JSON line ``{"revisions": ..., "write_s": [...]}`` and exits.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from services.simulator.commands import load_world
from services.simulator.groundtruth import ground_truth_features, ground_truth_grids
from shared.store import Feature, GridLayer, MapStore, RevisionWrite

log = logging.getLogger("bench._api_writer")

MAP_NAME = "site"
RESOLUTION_M = 0.05
PILLAR_KINDS = ("pillar", "rack_row", "bin")
PLACE_KINDS = ("corridor", "junction", "open_area", "room")
OTHER_KINDS = ("wall", "dock", "gate", "charger")


def _bin_feature(item: Mapping[str, Any]) -> Feature:
    """A ground-truth bin as the pillar stage stores one (id, aisle, bay, level, access pose, rows, centre)."""
    properties = item["properties"]
    ring = np.asarray(item["geometry"]["coordinates"][0], dtype=float)
    centre = ring[:-1].mean(axis=0)
    return Feature("bin", properties["id"], item["geometry"], {
        "kind": "bin", "id": properties["id"], "aisle": properties["aisle"], "bay": properties["bay"],
        "level": properties["level"], "access_pose": properties["access_pose"], "row": properties["row"],
        "back_row": None, "centre": [round(float(centre[0]), 4), round(float(centre[1]), 4)],
    }, 0.9)


def hall_features(*, seed: int) -> dict[str, list[Feature]]:
    """Every feature of the simulated 250 m x 72 m hall by kind, bins as the pillar stage writes them."""
    world = load_world("hall", seed=seed)
    by_kind: dict[str, list[Feature]] = {}
    for item in ground_truth_features(world)["features"]:
        kind = item["properties"]["kind"]
        if kind == "bin":
            feature = _bin_feature(item)
        else:
            properties = {name: value for name, value in item["properties"].items() if name != "track"}
            feature = Feature(kind, properties["id"], item["geometry"], properties, 1.0)
        by_kind.setdefault(kind, []).append(feature)
    return by_kind


def hall_occupancy(*, seed: int) -> GridLayer:
    """The hall's occupancy grid (int8, 5 cm) as the occupancy stage stores it."""
    grids = ground_truth_grids(load_world("hall", seed=seed), resolution_m=RESOLUTION_M)
    return GridLayer("occupancy", grids.occupancy, grids.resolution_m, grids.origin_x_m, grids.origin_y_m,
                     {"encoding": "occupancy"})


def _changed_occupancy(layer: GridLayer, rng: np.random.Generator) -> GridLayer:
    """``layer`` with a 2 m x 2 m patch of cells set to fresh random values, as new scans would."""
    data: npt.NDArray[np.int8] = layer.data.copy()
    side = int(2.0 / layer.resolution_m)
    row = int(rng.integers(0, data.shape[0] - side))
    col = int(rng.integers(0, data.shape[1] - side))
    data[row:row + side, col:col + side] = rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(side, side))
    return GridLayer(layer.name, data, layer.resolution_m, layer.origin_x_m, layer.origin_y_m, layer.meta)


def _nudged(bins: Sequence[Feature], rng: np.random.Generator) -> list[Feature]:
    """``bins`` with 1 % of them moved by a centimetre, as a refit of the rack rows would."""
    moved = set(rng.choice(len(bins), size=max(1, len(bins) // 100), replace=False).tolist())
    out = list(bins)
    for index in moved:
        item = bins[index]
        ring = (np.asarray(item.geometry["coordinates"][0]) + rng.normal(0.0, 0.01, 2)).round(4).tolist()
        out[index] = Feature(item.kind, item.key, {"type": "Polygon", "coordinates": [ring]}, item.properties,
                             item.confidence)
    return out


def write_hall(store: MapStore, map_id: int, features: Mapping[str, list[Feature]], occupancy: GridLayer) -> None:
    """The whole hall as the stages would have stored it: one revision per stage."""
    store.write_revision(map_id, RevisionWrite("occupancy_mapping", layers=[occupancy]))
    store.write_revision(map_id, RevisionWrite("grid_decomposition", features={
        kind: features[kind] for kind in (*PLACE_KINDS, *OTHER_KINDS) if kind in features}))
    store.write_revision(map_id, RevisionWrite("pillar_mapping",
                                               features={kind: features[kind] for kind in PILLAR_KINDS}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--database-url", required=True)
    parser.add_argument("--period-s", type=float, default=0.5, help="time between the starts of two revisions")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    rng = np.random.default_rng(args.seed)
    features = hall_features(seed=args.seed)
    occupancy = hall_occupancy(seed=args.seed)
    store = MapStore(args.database_url)
    map_id = store.ensure_map(MAP_NAME).id
    write_hall(store, map_id, features, occupancy)
    print(f"ready {len(features['bin'])}", flush=True)
    if sys.stdin.readline().strip() != "go":
        raise SystemExit("expected 'go' on stdin")
    stop = threading.Event()

    def wait_for_stop() -> None:
        sys.stdin.readline()
        stop.set()

    threading.Thread(target=wait_for_stop, daemon=True, name="stdin").start()
    write_s: list[float] = []
    stages = ("occupancy_mapping", "pillar_mapping")
    next_at = time.monotonic()
    while not stop.wait(max(0.0, next_at - time.monotonic())):
        next_at += args.period_s
        stage = stages[len(write_s) % 2]
        if stage == "occupancy_mapping":
            occupancy = _changed_occupancy(occupancy, rng)
            write = RevisionWrite(stage, layers=[occupancy])
        else:
            features["bin"] = _nudged(features["bin"], rng)
            write = RevisionWrite(stage, features={kind: features[kind] for kind in PILLAR_KINDS})
        started = time.perf_counter()
        store.write_revision(map_id, write)
        write_s.append(time.perf_counter() - started)
        next_at = max(next_at, time.monotonic())
    store.close()
    print(json.dumps({"revisions": len(write_s), "write_s": write_s}), flush=True)


if __name__ == "__main__":
    main()
