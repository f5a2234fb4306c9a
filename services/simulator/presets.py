"""Ready-made layouts: the small demo warehouse, the 250 m x 72 m hall, and seeded random ones."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from services.simulator.errors import SimulatorError


def demo_layout() -> dict[str, Any]:
    """A 40 m x 25 m warehouse: three aisles with a cross aisle, docks, a charger and some traffic."""
    return {
        "name": "demo",
        "hall": {"length_m": 40.0, "width_m": 25.0},
        "gates": [
            {"id": "G1", "kind": "dock", "edge": "south", "offset_m": 8.0, "width_m": 3.0},
            {"id": "G2", "kind": "dock", "edge": "south", "offset_m": 20.0, "width_m": 3.0},
            {"id": "D1", "kind": "door", "edge": "west", "offset_m": 20.0, "width_m": 1.0},
        ],
        "blocks": [
            {"id": "A", "origin_m": [5.0, 5.5], "aisles": 3, "bays": 10, "aisle_width_m": 3.0,
             "bay_pitch_m": 2.7, "rack_depth_m": 1.1, "levels": 4, "level_pitch_m": 1.5, "fill": 0.7,
             "cross_aisle_every": 5, "cross_aisle_width_m": 3.0, "end_corridor_m": 2.5},
        ],
        "open_areas": [{"id": "staging", "polygon": [[0.0, 0.0], [40.0, 0.0], [40.0, 3.0], [0.0, 3.0]]}],
        "chargers": [{"id": "C1", "pose": [38.0, 23.0, 0.0]}],
        "actors": [
            {"id": "F1", "kind": "forklift", "path": [[4.0, 1.8], [34.0, 1.8]], "speed_mps": 1.2},
            {"id": "P1", "kind": "person", "path": [[20.5, 6.0], [20.5, 19.0]], "speed_mps": 0.8},
            {"id": "L1", "kind": "pallet", "path": [[36.0, 12.0]], "speed_mps": 0.0},
        ],
        "seed": 0,
    }


def hall_layout() -> dict[str, Any]:
    """The 250 m x 72 m hall of paper A's experiment: 11 aisles of 81 bays, 3696 uprights."""
    return {
        "name": "hall",
        "hall": {"length_m": 250.0, "width_m": 72.0},
        "gates": [{"id": f"G{k + 1}", "kind": "dock", "edge": "south", "offset_m": 20.0 + 20.0 * k, "width_m": 3.5}
                  for k in range(10)],
        "blocks": [
            {"id": "A", "origin_m": [8.0, 8.0], "aisles": 11, "bays": 81, "aisle_width_m": 3.0,
             "bay_pitch_m": 2.7, "rack_depth_m": 1.1, "levels": 5, "level_pitch_m": 1.6, "fill": 0.75,
             "cross_aisle_every": 27, "cross_aisle_width_m": 3.0, "end_corridor_m": 4.0},
        ],
        "open_areas": [{"id": "staging", "polygon": [[0.0, 0.0], [250.0, 0.0], [250.0, 3.5], [0.0, 3.5]]}],
        "chargers": [{"id": f"C{k + 1}", "pose": [2.0 + 1.5 * k, 70.0, math.pi / 2]} for k in range(4)],
        "actors": [
            {"id": "F1", "kind": "forklift", "path": [[10.0, 5.0], [240.0, 5.0]], "speed_mps": 2.0},
            {"id": "F2", "kind": "forklift", "path": [[5.0, 10.0], [5.0, 65.0]], "speed_mps": 1.5},
            {"id": "P1", "kind": "person", "path": [[82.5, 10.0], [82.5, 65.0]], "speed_mps": 1.0},
        ],
        "seed": 0,
    }


def random_layout(seed: int, *, length_m: float | None = None, width_m: float | None = None,
                  rotated_region: bool | None = None) -> dict[str, Any]:
    """A seeded random warehouse layout: one rack block, optionally a second one rotated by an
    arbitrary angle in the open floor beside it, docks, doors, chargers, forklifts and people.

    Sizes not given are drawn (hall 50-120 m by 35-72 m).
    """
    rng = np.random.default_rng(seed)
    length = float(length_m if length_m is not None else rng.uniform(50.0, 120.0))
    width = float(width_m if width_m is not None else rng.uniform(35.0, 72.0))
    if length < 30.0 or width < 25.0:
        raise SimulatorError(f"a random hall needs at least 30 m x 25 m, got {length} x {width}")
    rotated = bool(rng.random() < 0.5) if rotated_region is None else rotated_region
    aisle_width = float(rng.choice([1.8, 2.8, 3.0, 3.2, 3.5]))
    depth = float(rng.uniform(1.0, 1.2))
    pitch = float(rng.uniform(2.6, 2.9))
    end = 3.0
    margin = 4.0
    usable_u = (0.6 if rotated else 1.0) * (length - 2 * margin) - 2 * end
    per_aisle = 2 * depth + 0.2 + aisle_width
    aisles = max(1, int((width - 2 * margin - 4.0) // per_aisle))
    every = int(rng.integers(6, 15))
    bays = max(2, int(usable_u // pitch))
    while bays > 2 and bays * pitch + (-(-bays // every) - 1) * 3.0 > usable_u:
        bays -= 1
    blocks: list[dict[str, Any]] = [{
        "id": "A", "origin_m": [margin + end, margin + 3.0], "aisles": aisles, "bays": bays,
        "aisle_width_m": aisle_width, "bay_pitch_m": pitch, "rack_depth_m": depth, "levels": int(rng.integers(3, 7)),
        "level_pitch_m": float(rng.uniform(1.3, 1.8)), "fill": float(rng.uniform(0.4, 0.9)),
        "cross_aisle_every": every, "cross_aisle_width_m": 3.0, "end_corridor_m": end,
    }]
    if rotated:
        x0 = margin + end + usable_u + 2 * end + 3.0
        room_u, room_v = length - margin - x0, width - 2 * margin - 3.0
        yaw = float(rng.uniform(-0.6, 0.6))
        side = min(room_u, room_v) / (abs(math.cos(yaw)) + abs(math.sin(yaw)))
        small_aisles = max(1, int((side - 2 * end) // (2 * depth + 0.2 + 3.0)))
        small_bays = max(2, int((side - 2 * end) // pitch))
        extent = small_bays * pitch
        span = small_aisles * (2 * depth + 3.0 + 0.2) - 0.2
        centre = np.array([x0 + 0.5 * room_u, margin + 3.0 + 0.5 * room_v])
        c, s = math.cos(yaw), math.sin(yaw)
        origin = centre - np.array([c * extent / 2 - s * span / 2, s * extent / 2 + c * span / 2])
        blocks.append({
            "id": "B", "origin_m": origin.round(3).tolist(), "yaw_rad": yaw, "aisles": small_aisles,
            "bays": small_bays, "aisle_width_m": 3.0, "bay_pitch_m": pitch, "rack_depth_m": depth, "levels": 3,
            "level_pitch_m": 1.5, "fill": 0.6, "end_corridor_m": 0.0,
        })
    docks = max(1, int(length // 20))
    gates: list[dict[str, Any]] = [{"id": f"G{k + 1}", "kind": "dock", "edge": "south",
                                    "offset_m": round(length * (k + 0.5) / docks - 1.5, 2), "width_m": 3.0}
                                   for k in range(docks)]
    gates.append({"id": "D1", "kind": "door", "edge": "west", "offset_m": round(width / 2, 2), "width_m": 1.0})
    staging = [[0.0, 0.0], [length, 0.0], [length, margin + 1.0], [0.0, margin + 1.0]]
    return {
        "name": f"random-{seed}",
        "hall": {"length_m": round(length, 3), "width_m": round(width, 3)},
        "gates": gates,
        "blocks": blocks,
        "open_areas": [{"id": "staging", "polygon": staging}],
        "chargers": [{"id": f"C{k + 1}", "pose": [length - 1.0, width - 2.0 - 1.5 * k, 0.0]} for k in range(2)],
        "actors": [
            {"id": "F1", "kind": "forklift", "path": [[3.0, 2.5], [length - 3.0, 2.5]], "speed_mps": 1.5},
            {"id": "P1", "kind": "person", "path": [[2.0, margin + 3.0], [2.0, width - margin]], "speed_mps": 0.9},
            {"id": "L1", "kind": "pallet", "path": [[length / 2, 2.0]], "speed_mps": 0.0},
        ],
        "seed": seed,
    }
