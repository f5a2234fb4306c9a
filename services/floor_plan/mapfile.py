"""Offline floor plan of a map file (``aisle floor-plan``): read YAML/PNG/PGM, fit, write GeoJSON and images."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from PIL import Image

from services.floor_plan.errors import FloorPlanError
from services.floor_plan.overview import overview_image
from services.floor_plan.pipeline import FloorPlan, FloorPlanSettings, floor_plan, room_labels, unit_labels
from services.floor_plan.rooms import room_keys
from shared.mapfiles import MapFileError, read_map_file
from shared.vocabulary import FeatureKind

logger = logging.getLogger(__name__)

def read_map(map_path: Path, *, resolution_m: float | None = None) -> tuple[npt.NDArray[np.int8], float,
                                                                               tuple[float, float]]:
    """Occupancy (GridLayer order: row 0 = lowest y), resolution and origin of a map_server YAML or bare image
    (:func:`shared.mapfiles.read_map_file`: a bare image needs ``resolution_m`` and has its origin at (0, 0)).

    A YAML is read as map_server reads it (its thresholds, its mode). A bare image declares no unknown grey: it is
    read with map_server's thresholds except that the image's own unknown grey and the speckle nearer it than white
    are unknown (:func:`shared.mapfiles.unknown_greys`), so that a map drawing unknown space light grey (230) or
    speckled with light grey inside rooms is not read as free there; and walls drawn light grey (a grey mode
    map_server reads as free, in long thin lines, with their outline) are occupied
    (:func:`shared.mapfiles.grey_walls`), so that no unit's free space lies on them. Free cells keep their darkness in
    percent (0..19; C_M reads them free all the same), so the grey edge along the walls can be told from clear floor
    (:func:`~services.floor_plan.rooms.wall_fringe`).

    Raises
    ------
    FloorPlanError
        Missing or unreadable files, malformed YAML, a bare image without a resolution.
    """
    try:
        image = read_map_file(Path(map_path), resolution_m=resolution_m, free_from_modes=True,
                              free_darkness=True)
    except MapFileError as err:
        raise FloorPlanError(str(err)) from err
    return image.occupancy, image.resolution_m, (image.origin_x_m, image.origin_y_m)


def geojson(plan: FloorPlan) -> dict[str, Any]:
    """GeoJSON FeatureCollection: unit polygons (type, probability, neighbours, the keys of the rooms the unit is
    part of: one, or several where the room level cuts it at a wall it stands over), door segments and the
    solid obstacles (polygons; ``standing``: a block in the building rather than a filled outside)."""
    neighbours: dict[int, list[int]] = {u.id: [] for u in plan.units}
    for a, b in plan.adjacency:
        neighbours[a].append(b)
        neighbours[b].append(a)
    rooms: dict[int, list[str]] = {u.id: [] for u in plan.units}
    for key, room in zip(room_keys(plan.rooms), plan.rooms, strict=True):
        for u in room.units:
            rooms[u].append(key)
    features: list[dict[str, Any]] = [
        {
            "type": "Feature",
            "geometry": {"type": "Polygon", "coordinates": [[list(p) for p in u.polygon_xy_m]]},
            "properties": {"kind": FeatureKind.UNIT, "id": u.id, "label": str(u.unit_type),
                           "probability": round(u.probability, 4), "area_m2": round(u.area_m2, 3),
                           "adjacent": sorted(neighbours[u.id]), "rooms": rooms[u.id]},
        }
        for u in plan.units
    ]
    features += [
        {
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": [list(p) for p in d.segment_xy_m]},
            "properties": {"kind": FeatureKind.DOOR, "id": i, "units": list(d.units), "width_m": round(d.width_m, 3)},
        }
        for i, d in enumerate(plan.doors)
    ]
    features += [
        {
            "type": "Feature",
            "geometry": {"type": "Polygon", "coordinates": [[list(p) for p in ring] for ring in polygon]},
            "properties": {"kind": FeatureKind.OBSTACLE, "id": i, "standing": standing},
        }
        for i, (polygon, standing) in enumerate(zip(plan.obstacles, plan.standing, strict=True))
    ]
    return {"type": "FeatureCollection", "features": features,
            "properties": {"k": round(plan.k, 6), "k_units": round(plan.k_units, 6),
                           "clutter": plan.clutter, "wall_segments": plan.wall_segments,
                           "slanted_walls": plan.slanted_walls, "exterior": plan.exterior,
                           "iterations": plan.iterations}}


def write_outputs(plan: FloorPlan, out_dir: Path) -> dict[str, Path]:
    """Write floor_plan.geojson, units.png and rooms.png (16-bit unit / room ids on free cells: :func:`unit_labels`,
    :func:`room_labels`) and overview.png; image rows top = high y."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise FloorPlanError(f"cannot create output folder {out}: {err}") from err
    paths = {"geojson": out / "floor_plan.geojson", "units": out / "units.png", "rooms": out / "rooms.png",
             "overview": out / "overview.png"}
    images = {"units": unit_labels(plan), "rooms": room_labels(plan)}
    for name, labels in images.items():
        if labels.max() > np.iinfo(np.uint16).max:
            raise FloorPlanError(f"{name[:-1]} id {labels.max()} does not fit a 16-bit {name}.png")
    paths["geojson"].write_text(json.dumps(geojson(plan)))
    for name, labels in images.items():
        cv2.imwrite(str(paths[name]), np.ascontiguousarray(labels[::-1].astype(np.uint16)))
    Image.fromarray(overview_image(plan)).save(paths["overview"])
    return paths


def read_trajectory(path: Path) -> npt.NDArray[np.float64]:
    """Robot positions from a CSV file: x, y in map metres, one position a line (more columns are ignored).

    Raises
    ------
    FloorPlanError
        A missing or unreadable file, fewer than two columns, or positions that are not finite numbers.
    """
    try:
        xy = np.loadtxt(path, delimiter=",", usecols=(0, 1), ndmin=2, dtype=np.float64)
    except (OSError, ValueError) as err:
        raise FloorPlanError(f"cannot read robot positions (x,y per line, metres) from {path}: {err}") from err
    if not np.isfinite(xy).all():
        raise FloorPlanError(f"robot positions in {path} must be finite numbers")
    return xy


def floor_plan_map_file(map_path: Path, out_dir: Path, *, resolution_m: float | None = None,
                        settings: FloorPlanSettings | None = None,
                        trajectory_xy_m: npt.NDArray[np.float64] | None = None) -> FloorPlan:
    """Fit a floor plan to a map file and write its outputs (the ``aisle floor-plan`` command).

    Raises
    ------
    FloorPlanError
        Missing, unreadable or malformed map files; maps too small or without free space.
    """
    occ, res, origin = read_map(Path(map_path), resolution_m=resolution_m)
    plan = floor_plan(occ, resolution_m=res, origin_xy_m=origin, settings=settings, trajectory_xy_m=trajectory_xy_m)
    write_outputs(plan, Path(out_dir))
    logger.info("floor plan of %s: %d units, %d doors into %s", map_path, len(plan.units), len(plan.doors), out_dir)
    return plan
