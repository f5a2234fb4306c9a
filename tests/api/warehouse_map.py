"""A small simulated warehouse written to a map store as the stages would write it (navigation tests).

Two aisles of eight bays in two sections (a cross aisle between them), empty racks, a perimeter
aisle, two dock gates in the south wall and a charger by the west wall. Its ground-truth occupancy
is decomposed once per test session; :func:`write_warehouse` stores the occupancy layer, the
decomposition (layers, region features, topology), the bins as the pillar stage writes them and
the docks and charger as ground-truth features.
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

from services.grid_decomposition import decompose
from services.grid_decomposition.pipeline import Decomposition
from services.grid_decomposition.records import decomposition_features, decomposition_layers, decomposition_topology
from services.simulator import GroundTruthGrids, World, ground_truth_grids, world_from_layout
from shared.store import Feature, GridLayer, MapInfo, MapStore, RevisionWrite

PITCH_M = 2.7
LAYOUT: dict[str, Any] = {
    "name": "nav-test",
    "hall": {"length_m": 30.6, "width_m": 16.6},
    "gates": [{"id": "G1", "kind": "dock", "edge": "south", "offset_m": 4.0, "width_m": 3.0},
              {"id": "G2", "kind": "dock", "edge": "south", "offset_m": 23.0, "width_m": 3.0}],
    "blocks": [{"id": "A", "origin_m": [3.0, 3.0], "aisles": 2, "bays": 8, "aisle_width_m": 3.0,
                "bay_pitch_m": PITCH_M, "rack_depth_m": 1.1, "levels": 3, "level_pitch_m": 1.5, "fill": 0.0,
                "cross_aisle_every": 4, "cross_aisle_width_m": 3.0, "end_corridor_m": 3.0}],
    "open_areas": [],
    "chargers": [{"id": "C1", "pose": [1.0, 8.0, math.pi]}],
    "actors": [],
    "seed": 0,
}
GROUND_TRUTH_STAGE = "ground_truth"


class Warehouse(NamedTuple):
    world: World
    grids: GroundTruthGrids
    decomposition: Decomposition


@functools.cache
def warehouse() -> Warehouse:
    """The world, its ground-truth occupancy (5 cm) and the decomposition of that occupancy (cached)."""
    world = world_from_layout(LAYOUT)
    grids = ground_truth_grids(world, resolution_m=0.05)
    decomposition = decompose(grids.occupancy, resolution_m=grids.resolution_m,
                              origin_xy_m=(grids.origin_x_m, grids.origin_y_m))
    return Warehouse(world, grids, decomposition)


def bin_features(world: World) -> list[Feature]:
    """The world's bins as the pillar stage writes them (footprint polygon; id, aisle, bay, level, access pose)."""
    out = []
    for b in world.bins:
        ring = [[float(x), float(y)] for x, y in b.polygon]
        out.append(Feature("bin", b.id, {"type": "Polygon", "coordinates": [[*ring, ring[0]]]}, {
            "kind": "bin", "id": b.id, "aisle": b.aisle, "bay": b.bay, "level": b.level,
            "access_pose": list(b.access_pose), "row": b.row, "back_row": None,
            "centre": [float(b.polygon[:, 0].mean()), float(b.polygon[:, 1].mean())], "z_m": b.z_m,
        }, 0.9))
    return out


def place_features(world: World) -> dict[str, list[Feature]]:
    """Docks (lines across their gate) and chargers (points with their docking pose), as in the ground truth."""
    docks = [Feature("dock", g.id, {"type": "LineString", "coordinates": [list(g.a), list(g.b)]},
                     {"gate_kind": g.kind}) for g in world.gates if g.kind == "dock"]
    chargers = [Feature("charger", c.id, {"type": "Point", "coordinates": list(c.pose[:2])}, {"pose": list(c.pose)})
                for c in world.chargers]
    return {"dock": docks, "charger": chargers}


def write_warehouse(store: MapStore, *, map_name: str = "site") -> MapInfo:
    """Store the warehouse in map ``map_name``: occupancy, decomposition, bins, docks and charger (4 revisions)."""
    wh = warehouse()
    info = store.ensure_map(map_name)
    grids = wh.grids
    occupancy = GridLayer("occupancy", grids.occupancy, grids.resolution_m, grids.origin_x_m, grids.origin_y_m,
                          {"encoding": "occupancy"})
    source = store.write_revision(info.id, RevisionWrite("occupancy_mapping", layers=[occupancy])).id
    store.write_revision(info.id, RevisionWrite(
        "grid_decomposition",
        layers=decomposition_layers(wh.decomposition, meta={"source_layer": "occupancy", "source_revision": source}),
        features=decomposition_features(wh.decomposition),
        topology=decomposition_topology(wh.decomposition),
    ))
    store.write_revision(info.id, RevisionWrite("pillar_mapping", features={"bin": bin_features(wh.world)}))
    store.write_revision(info.id, RevisionWrite(GROUND_TRUTH_STAGE, features=place_features(wh.world)))
    return info
