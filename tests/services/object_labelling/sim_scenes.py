"""Simulated warehouse scenes for the worker tests: a small hall, a classifier trained on renders, and
per-cone ground truth by ray casting.

The test hall has one rack block at the back and a forklift, a person and a loose pallet standing
in front of it; the robot drives along ``y = 2 m`` with the RGB-D camera looking left at them. The
classifier is trained on renders of *other* halls (the scatter halls of
:mod:`services.labelling_training.sim_views`: other positions, headings and distances).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from services.simulator import World, world_from_layout
from services.simulator.actors import dynamic_boxes
from services.simulator.lidar import Segments, cast_rays
from services.simulator.world import ObjectClass, concat_boxes

ROI_OF_KIND = {ObjectClass.PALLET: "pallet", ObjectClass.LOAD: "pallet", ObjectClass.FORKLIFT: "forklift",
               ObjectClass.PERSON: "human"}
"""Labeller ROI class of each simulated object class; anything else is background."""
ROBOT_Y_M = 2.0


def _layout(name: str, actors: list[dict[str, Any]], *, seed: int) -> dict[str, Any]:
    return {
        "name": name,
        "hall": {"length_m": 24.0, "width_m": 14.0},
        "gates": [{"id": "G1", "kind": "dock", "edge": "north", "offset_m": 20.0, "width_m": 3.0}],
        "blocks": [{"id": "A", "origin_m": [2.0, 8.0], "aisles": 1, "bays": 6, "aisle_width_m": 3.0,
                    "bay_pitch_m": 2.7, "rack_depth_m": 1.1, "levels": 3, "level_pitch_m": 1.5, "fill": 0.7,
                    "cross_aisle_every": 10, "cross_aisle_width_m": 3.0, "end_corridor_m": 1.0}],
        "open_areas": [],
        "chargers": [],
        "actors": actors,
        "seed": seed,
    }


def labelling_hall() -> World:
    """The hall the robot drives through: objects 2.5-3.5 m to the left of its path."""
    return world_from_layout(_layout("labelling-test", [
        {"id": "F1", "kind": "forklift", "path": [[6.0, 5.0]], "speed_mps": 0.0},
        {"id": "P1", "kind": "person", "path": [[11.0, 4.6], [12.0, 4.6]], "speed_mps": 0.2},
        {"id": "L1", "kind": "pallet", "path": [[16.0, 4.8]], "speed_mps": 0.0},
    ], seed=3))


def robot_waypoints() -> list[list[float]]:
    """The robot's straight route past the objects."""
    return [[2.0, ROBOT_Y_M], [19.0, ROBOT_Y_M]]


def cone_truth(world: World, time_s: float, origin_xy: npt.NDArray[np.float64],
               bearings_map_rad: npt.NDArray[np.float64], heights_m: npt.NDArray[np.float64]) -> list[str]:
    """Per cone, the labeller class of the first box a horizontal ray hits at half the cone's height
    (``"background"`` for racks, walls and the rest, ``"none"`` when nothing is hit within 6 m)."""
    scene = concat_boxes([world.boxes, dynamic_boxes(world, time_s)])
    out = []
    cuts: dict[float, Segments] = {}
    for bearing, height in zip(bearings_map_rad, heights_m, strict=True):
        cut = round(max(0.08, 0.5 * float(height)), 1)
        segments = cuts.get(cut) or cuts.setdefault(cut, Segments.from_boxes(scene, height_m=cut))
        _, hit = cast_rays(origin_xy, float(bearing), 1e-3, 1, [(segments, None)], max_range_m=6.0)
        kind = int(hit[0])
        out.append("none" if kind < 0 else ROI_OF_KIND.get(ObjectClass(kind), "background"))
    return out
