"""Maps whose walls run at an angle: explained in a turned frame, units turned back into the map."""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan import SEED_SCHEDULE, ChainSettings, FloorPlanSettings, Phase, World, floor_plan, unit_labels
from services.floor_plan.frame import Frame, carry, make_frame, points_to_map
from services.floor_plan.world import Rect

RES = 0.05
SHORT = tuple(Phase(None if p.until is None else p.until // 4, p.probabilities) for p in SEED_SCHEDULE)


def _turned_two_rooms(degrees: float) -> npt.NDArray[np.int8]:
    """Two walled rooms sharing a wall with a door, turned by ``degrees`` about the centre."""
    occ = np.full((120, 200), -1, np.int8)
    for r0, r1, c0, c1 in ((20, 99, 20, 100), (20, 99, 99, 180)):
        occ[r0 : r1 + 1, c0 : c1 + 1] = 100
        occ[r0 + 2 : r1 - 1, c0 + 2 : c1 - 1] = 0
    occ[50:70, 99:101] = 0
    turn = cv2.getRotationMatrix2D((100.0, 60.0), degrees, 1.0)
    grey = cv2.warpAffine((occ.astype(np.int16) + 1).astype(np.uint8), turn, (260, 180), flags=cv2.INTER_NEAREST)
    return (grey.astype(np.int16) - 1).astype(np.int8)


def test_a_turned_map_is_explained_by_units_along_its_walls() -> None:
    occ = _turned_two_rooms(17.0)
    settings = FloorPlanSettings(chain=ChainSettings(iterations=3000, seed=1, schedule=SHORT))
    plan = floor_plan(occ, resolution_m=RES, settings=settings)
    upright = floor_plan(occ, resolution_m=RES, settings=settings, angle_rad=0.0)
    assert len(plan.units) == 2
    for unit in plan.units:  # every side of every unit runs along the rooms' walls, up to a degree
        ring = np.array(unit.polygon_xy_m)
        for (x0, y0), (x1, y1) in itertools.pairwise(ring):
            direction = math.degrees(math.atan2(y1 - y0, x1 - x0)) % 90.0
            assert min(abs(direction - 73.0), abs(direction - 17.0)) < 1.0, direction
    assert plan.k > upright.k, "units along the walls explain the map better than upright ones"
    labels = unit_labels(plan)
    assert set(np.unique(labels[occ == 0])) <= {0} | {u.id for u in plan.units}
    assert np.mean(labels[occ == 0] > 0) > 0.9, "the label image covers the rooms' free cells"


def test_a_world_carried_into_the_frame_of_a_grown_map_stays_where_it_was() -> None:
    angle = math.radians(20.0)
    old = make_frame((100, 150), angle_rad=angle, origin_xy_m=(2.0, -1.0), resolution_m=RES)
    new = make_frame((130, 190), angle_rad=angle, origin_xy_m=(0.5, -2.0), resolution_m=RES)
    world = World({1: Rect(30, 60, 40, 90), 2: Rect(59, 90, 40, 90)}, {Rect(59, 60, 50, 60)}, 3)
    moved = carry(world, old, new)

    def metres(frame: Frame, r: Rect) -> npt.NDArray[np.float64]:
        rc = points_to_map(frame, np.array([[r.r0, r.c0], [r.r1 + 1, r.c1 + 1]], np.float64))
        return np.array(frame.origin_xy_m)[::-1] + rc * RES  # (y, x)

    for uid, rect in world.units.items():
        assert np.abs(metres(old, rect) - metres(new, moved.units[uid])).max() <= RES
    assert moved.units[1].r1 - moved.units[2].r0 == 1, "the shared wall stays shared"
    assert len(moved.doors) == 1
