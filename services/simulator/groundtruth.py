"""Ground truth of a world: GeoJSON features, a lidar-height occupancy grid and a place-label image.

The label image and the occupancy grid share one frame (:class:`GroundTruthGrids`), so every
occupancy cell has its label: 0 none or occupied, 1 corridor, 2 junction, 3 storage, 4 room,
5 open area, 6 unidentified free floor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.simulator.errors import SimulatorError
from services.simulator.world import AreaKind, FloatArray, World
from shared.vocabulary import FeatureKind, PlaceLabel

UNIDENTIFIED_FREE = int(PlaceLabel.UNIDENTIFIED)
"""Label of free floor no area claims."""
_PAINT_ORDER = (AreaKind.OPEN_AREA, AreaKind.ROOM, AreaKind.STORAGE, AreaKind.CORRIDOR, AreaKind.JUNCTION)
_SHIFT = 4


class GroundTruthGrids(NamedTuple):
    """Occupancy (int8: 100 occupied, 0 free, -1 outside) and labels (uint8) on one grid.

    ``data[row, col]`` as :class:`shared.store.GridLayer`: row 0 is the lowest y; the cell's lower-left
    corner is ``(origin_x_m + col * resolution_m, origin_y_m + row * resolution_m)``.
    """

    occupancy: npt.NDArray[np.int8]
    labels: npt.NDArray[np.uint8]
    resolution_m: float
    origin_x_m: float
    origin_y_m: float


def _ring(polygon: FloatArray) -> list[list[float]]:
    points = [[round(float(x), 4), round(float(y), 4)] for x, y in polygon]
    return [*points, points[0]]


def _feature(kind: FeatureKind, key: str, geometry: dict[str, Any], **properties: Any) -> dict[str, Any]:
    return {"type": "Feature", "geometry": geometry, "properties": {"kind": kind, "id": key, **properties}}


def ground_truth_features(world: World, *, tracks: Mapping[str, FloatArray] | None = None) -> dict[str, Any]:
    """A GeoJSON FeatureCollection (map metres) of everything a map of ``world`` should contain.

    Feature ``properties.kind`` is one of the store's feature kinds: ``wall`` (LineString),
    ``corridor``, ``junction``, ``room``, ``open_area``, ``rack_row`` and ``bin`` (Polygons), ``pillar``
    (Point per upright), ``dock`` and ``gate`` (door; LineStrings across the opening), ``charger`` (Point,
    with its docking pose), ``object`` (actor path, with sampled ``track`` [t, x, y, yaw] rows when
    ``tracks`` maps the actor id to an (n, 4) array).
    """
    features = [_feature(FeatureKind.WALL, f"W{i}", {"type": "LineString", "coordinates": seg.round(4).tolist()})
                for i, seg in enumerate(world.walls)]
    for area in world.areas:
        if area.kind is AreaKind.STORAGE:
            continue  # the rack_row features below carry the storage footprints
        polygon = {"type": "Polygon", "coordinates": [_ring(area.polygon)]}
        features.append(_feature(FeatureKind[area.kind.name], area.id, polygon, label=area.kind.value,
                                 **dict(area.detail)))
    for row in world.rows:
        polygon = {"type": "Polygon", "coordinates": [_ring(row.polygon)]}
        features.append(_feature(FeatureKind.RACK_ROW, row.id, polygon, aisle=row.aisle,
                                 front_yaw_rad=row.front_yaw_rad, bays=row.bays, levels=row.levels))
    for b in world.bins:
        features.append(_feature(FeatureKind.BIN, b.id, {"type": "Polygon", "coordinates": [_ring(b.polygon)]},
                                 row=b.row, aisle=b.aisle, bay=b.bay, level=b.level, z_m=b.z_m,
                                 access_pose=[round(v, 4) for v in b.access_pose], occupied=b.occupied))
    for (x, y), uid, row_index in zip(world.uprights.xy, world.uprights.ids, world.uprights.row, strict=True):
        point = {"type": "Point", "coordinates": [round(float(x), 4), round(float(y), 4)]}
        features.append(_feature(FeatureKind.PILLAR, uid, point, row=world.rows[int(row_index)].id))
    for gate in world.gates:
        line = {"type": "LineString", "coordinates": [list(gate.a), list(gate.b)]}
        kind = FeatureKind.DOCK if gate.kind == "dock" else FeatureKind.GATE
        features.append(_feature(kind, gate.id, line, gate_kind=gate.kind))
    for charger in world.chargers:
        spot = {"type": "Point", "coordinates": list(charger.pose[:2])}
        features.append(_feature(FeatureKind.CHARGER, charger.id, spot, pose=list(charger.pose)))
    for actor in world.actors:
        path = actor.path if len(actor.path) > 1 else np.vstack([actor.path, actor.path])
        extra = {"track": np.asarray(tracks[actor.id]).round(4).tolist()} if tracks and actor.id in tracks else {}
        line = {"type": "LineString", "coordinates": path.round(4).tolist()}
        features.append(_feature(FeatureKind.OBJECT, actor.id, line, object_class=actor.kind.value,
                                 speed_mps=actor.speed_mps, **extra))
    return {"type": "FeatureCollection", "name": world.name, "features": features}


def _to_cells(points: FloatArray, origin: FloatArray, resolution_m: float) -> npt.NDArray[np.int32]:
    return np.round((points - origin) / resolution_m * (1 << _SHIFT) - 0.5 * (1 << _SHIFT)).astype(np.int32)


def lidar_footprints(world: World, *, height_m: float) -> FloatArray:
    """Footprint corners (n, 4, 2) of the static boxes a horizontal scan at ``height_m`` cuts."""
    z = world.boxes.z_m
    return world.boxes.take((z[:, 0] <= height_m) & (z[:, 1] >= height_m)).corners_xy()


def ground_truth_grids(world: World, *, resolution_m: float = 0.05, height_m: float = 0.2,
                       margin_m: float = 1.0) -> GroundTruthGrids:
    """Rasterise ``world``'s static obstacles at ``height_m`` and its place labels.

    Parameters
    ----------
    world : World
        The world.
    resolution_m : float
        Cell size, metres.
    height_m : float
        Height of the horizontal cut (the lidar's mounting height), metres.
    margin_m : float
        Extra border around the world's bounds, metres.
    """
    if not (math.isfinite(resolution_m) and resolution_m > 0):
        raise SimulatorError(f"resolution_m must be positive, got {resolution_m}")
    x0, y0, x1, y1 = world.bounds
    origin = np.floor(np.array([x0 - margin_m, y0 - margin_m]) / resolution_m) * resolution_m
    cols = math.ceil((x1 + margin_m - origin[0]) / resolution_m)
    rows = math.ceil((y1 + margin_m - origin[1]) / resolution_m)
    if rows * cols > 400_000_000:
        raise SimulatorError(f"a {rows} x {cols} grid at {resolution_m} m is too large")
    labels = np.zeros((rows, cols), np.uint8)
    cv2.fillPoly(labels, [_to_cells(world.outline, origin, resolution_m)], UNIDENTIFIED_FREE, cv2.LINE_8, _SHIFT)
    inside = labels > 0
    for kind in _PAINT_ORDER:
        polygons = [_to_cells(a.polygon, origin, resolution_m) for a in world.areas if a.kind is kind]
        if polygons:
            cv2.fillPoly(labels, polygons, kind.value, cv2.LINE_8, _SHIFT)
    occupied = np.zeros((rows, cols), np.uint8)
    footprints = [_to_cells(c, origin, resolution_m) for c in lidar_footprints(world, height_m=height_m)]
    if footprints:
        cv2.fillPoly(occupied, footprints, 1, cv2.LINE_8, _SHIFT)
        cv2.polylines(occupied, footprints, True, 1, 1, cv2.LINE_8, _SHIFT)
    occupancy = np.where(occupied > 0, 100, np.where(inside, 0, -1)).astype(np.int8)
    labels[(occupied > 0) | ~inside] = 0
    return GroundTruthGrids(occupancy, labels, resolution_m, float(origin[0]), float(origin[1]))


def surface_mask(world: World, grids: GroundTruthGrids, *, height_m: float = 0.2) -> npt.NDArray[np.bool_]:
    """Cells of ``grids`` crossed by the outline of a static obstacle at ``height_m`` (what a lidar can hit)."""
    origin = np.array([grids.origin_x_m, grids.origin_y_m])
    mask = np.zeros(grids.occupancy.shape, np.uint8)
    footprints = [_to_cells(c, origin, grids.resolution_m) for c in lidar_footprints(world, height_m=height_m)]
    cv2.polylines(mask, footprints, True, 1, 1, cv2.LINE_8, _SHIFT)
    return mask > 0


def uprights_csv(world: World) -> str:
    """``id,x_m,y_m,row`` lines of every upright."""
    lines = ["id,x_m,y_m,row"]
    lines += [f"{uid},{x:.4f},{y:.4f},{world.rows[int(r)].id}"
              for (x, y), uid, r in zip(world.uprights.xy, world.uprights.ids, world.uprights.row, strict=True)]
    return "\n".join(lines) + "\n"

