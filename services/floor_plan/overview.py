"""A picture of a floor plan: the map in grey, units coloured by type, walls blue, doors cyan."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan.pipeline import FloorPlan
from services.floor_plan.world import UnitType

TYPE_COLOURS: dict[UnitType, tuple[int, int, int]] = {
    UnitType.ROOM: (190, 160, 230),
    UnitType.CORRIDOR: (120, 200, 120),
    UnitType.HALL: (240, 170, 60),
    UnitType.OTHER: (200, 200, 200),
}
WALL_COLOUR = (30, 60, 230)
DOOR_COLOUR = (0, 220, 230)


def overview_image(plan: FloorPlan, *, scale: int | None = None) -> npt.NDArray[np.uint8]:
    """RGB (top row = highest y): C_M in grey levels, unit fill by type (half-tone), walls, doors, legend.

    Returns
    -------
    (H', W', 3) uint8, the map enlarged by ``scale`` (default: to about 1500 px on the longer side).
    """
    h, w = plan.classes_map.shape
    k = scale or max(1, 1500 // max(h, w))
    grey = np.array([255, 160, 0], np.uint8)[plan.classes_map]
    rgb = np.repeat(grey[..., None], 3, axis=2).astype(np.float64)
    for unit in plan.units:
        r = unit.rect
        sl = (slice(r.r0, r.r1 + 1), slice(r.c0, r.c1 + 1))
        rgb[sl] = 0.5 * rgb[sl] + 0.5 * np.array(TYPE_COLOURS[unit.unit_type])
    out = np.ascontiguousarray(np.kron(rgb, np.ones((k, k, 1))).astype(np.uint8))
    for unit in plan.units:
        r = unit.rect
        cv2.rectangle(out, (r.c0 * k, r.r0 * k), ((r.c1 + 1) * k - 1, (r.r1 + 1) * k - 1), WALL_COLOUR,
                      max(1, k // 2))
    for door in plan.doors:
        d = door.rect
        cv2.rectangle(out, (d.c0 * k, d.r0 * k), ((d.c1 + 1) * k - 1, (d.r1 + 1) * k - 1), DOOR_COLOUR, -1)
    out = np.ascontiguousarray(out[::-1])
    y = 20
    for t, colour in TYPE_COLOURS.items():
        cv2.rectangle(out, (8, y - 12), (24, y + 2), colour, -1)
        cv2.putText(out, str(t), (30, y), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        y += 20
    cv2.putText(out, f"K(W,M) {100 * plan.k:.1f} %  units {len(plan.units)}  doors {len(plan.doors)}", (8, y),
                cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return out
