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
    ox, oy = plan.origin_xy_m

    def pixels(points: tuple[tuple[float, float], ...], scale: int) -> npt.NDArray[np.int32]:
        """Map metres -> (x, y) pixels of an image ``scale`` times the map."""
        xy = np.array(points, np.float64)
        return np.rint(np.stack([(xy[:, 0] - ox) / plan.resolution_m * scale,
                                 (xy[:, 1] - oy) / plan.resolution_m * scale], axis=1)).astype(np.int32)

    for unit in plan.units:
        mask = np.zeros((h, w), np.uint8)
        cv2.fillPoly(mask, [pixels(unit.polygon_xy_m[:4], 1)], 1)
        inside = mask.astype(bool)
        rgb[inside] = 0.5 * rgb[inside] + 0.5 * np.array(TYPE_COLOURS[unit.unit_type])
    out = np.ascontiguousarray(np.kron(rgb, np.ones((k, k, 1))).astype(np.uint8))
    for unit in plan.units:
        cv2.polylines(out, [pixels(unit.polygon_xy_m[:4], k)], True, WALL_COLOUR, max(1, k // 2))
    for door in plan.doors:
        a, b = pixels(door.segment_xy_m, k)
        cv2.line(out, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), DOOR_COLOUR, max(2, k))
    out = np.ascontiguousarray(out[::-1])
    y = 20
    for t, colour in TYPE_COLOURS.items():
        cv2.rectangle(out, (8, y - 12), (24, y + 2), colour, -1)
        cv2.putText(out, str(t), (30, y), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        y += 20
    cv2.putText(out, f"K(W,M) {100 * plan.k:.1f} %  units {len(plan.units)}  doors {len(plan.doors)}", (8, y),
                cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return out
