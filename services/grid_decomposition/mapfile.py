"""Offline decomposition of a map file: read YAML/PNG/PGM, decompose, write images, GeoJSON, topology."""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import numpy.typing as npt
from PIL import Image

from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.overview import overview_image
from services.grid_decomposition.pipeline import Decomposition, decompose
from services.grid_decomposition.semantics import parse_label
from services.grid_decomposition.subdivision import line_endpoints
from shared.mapfiles import IMAGE_SUFFIXES, MapFileError
from shared.mapfiles import read_map_file as shared_read_map_file
from shared.vocabulary import FeatureKind, PlaceLabel

if TYPE_CHECKING:
    import networkx as nx

logger = logging.getLogger(__name__)



def read_map_file(
    map_path: Path, *, resolution_m: float | None = None
) -> tuple[npt.NDArray[np.int8], float, tuple[float, float]]:
    """Occupancy (GridLayer order), resolution and origin of a map_server YAML or a bare image
    (:func:`shared.mapfiles.read_map_file`). A bare image's free cells keep their darkness in percent (0..19):
    grey fringes at walls are not clearly free (:func:`~services.grid_decomposition.cleaning.clean_occupancy`).
    """
    path = Path(map_path)
    try:
        image = shared_read_map_file(path, resolution_m=resolution_m, free_darkness=True)
    except MapFileError as err:
        raise DecompositionError(f"{err}{_missing_image_hint(path, err)}") from err
    return image.occupancy, image.resolution_m, (image.origin_x_m, image.origin_y_m)


def _missing_image_hint(yaml_path: Path, err: MapFileError) -> str:
    """For a YAML whose image is missing: the images beside it and how to decompose one of them."""
    if not isinstance(err.__cause__, FileNotFoundError) or not yaml_path.exists():
        return ""
    beside = sorted(p.name for p in yaml_path.parent.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not beside:
        return ""
    return (
        f"; {yaml_path.parent} holds {', '.join(beside)}: fix the YAML's 'image:' if one of them is this map, "
        f"or decompose it as a bare image, e.g. aisle decompose {yaml_path.parent / beside[0]} --resolution R "
        "--out DIR (origin (0, 0); the YAML's origin belongs to its own image)"
    )


def parse_label_overrides(text: str) -> dict[int, PlaceLabel]:
    """``"0=corridor,3=storage"`` -> {0: CORRIDOR, 3: STORAGE} (the CLI's ``--labels``)."""
    out: dict[int, PlaceLabel] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip().lstrip("-").isdigit():
            raise DecompositionError(f"label override {item!r} is not CATEGORY=LABEL (e.g. 3=storage)")
        out[int(key)] = parse_label(value)
    return out


def _to_metres(points_px: npt.NDArray[np.float64], decomposition: Decomposition) -> list[list[float]]:
    """(x = column, y = row) grid pixel coordinates (cell corners) to map metres."""
    ox, oy = decomposition.origin_xy_m
    res = decomposition.resolution_m
    return [[round(ox + float(x) * res, 4), round(oy + float(y) * res, 4)] for x, y in points_px]


def layout_features(decomposition: Decomposition) -> dict[str, Any]:
    """GeoJSON FeatureCollection of regions (polygons), walls (cogent edges) and decomposition lines."""
    from scipy import ndimage  # imported when first needed

    features: list[dict[str, Any]] = []
    seg = decomposition.segments
    for sid, box in enumerate(ndimage.find_objects(seg), start=1):
        if box is None or sid not in decomposition.regions:
            continue
        info = decomposition.regions[sid]
        mask = np.pad((seg[box] == sid).astype(np.uint8), 1)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        polys = []
        for c in contours:
            if len(c) < 3:
                continue
            pts = c.reshape(-1, 2).astype(np.float64) - 1 + [box[1].start, box[0].start] + 0.5
            ring = _to_metres(pts, decomposition)
            polys.append([[*ring, ring[0]]])
        if not polys:
            continue
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "MultiPolygon", "coordinates": polys},
                "properties": {
                    "kind": FeatureKind.REGION,
                    "id": sid,
                    "label": info.label.name.lower(),
                    "category": info.category,
                    "area_m2": round(info.area_m2, 3),
                },
            }
        )
    sub, cog = decomposition.subdivision, decomposition.cogency
    for e in np.flatnonzero(cog.cogent):
        ends = sub.edge_ends_px[e] + 0.5
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": _to_metres(ends, decomposition)},
                "properties": {
                    "kind": FeatureKind.WALL,
                    "id": int(e),
                    "label": "door" if cog.door[e] else "wall",
                    "category": None,
                },
            }
        )
    h, w = seg.shape
    n_line = 0
    for g_index, group in enumerate(decomposition.line_groups):
        for line in group.lines:
            seg_pts = _clip_line(line_endpoints(line, (h, w)), group.mask, (h, w))
            for p0, p1 in seg_pts:
                features.append(
                    {
                        "type": "Feature",
                        "geometry": {
                            "type": "LineString",
                            "coordinates": _to_metres(np.array([p0, p1], dtype=np.float64) + 0.5, decomposition),
                        },
                        "properties": {
                            "kind": FeatureKind.LINE,
                            "id": n_line,
                            "label": "coarse" if line.coarse else "fine",
                            "category": g_index,
                            "angle_rad": round(line.angle_rad, 6),
                            "support_m": round(line.support_m, 3),
                        },
                    }
                )
                n_line += 1
    return {"type": "FeatureCollection", "features": features}


def _clip_line(
    ends: tuple[tuple[int, int], tuple[int, int]], mask: npt.NDArray[np.bool_] | None, shape: tuple[int, int]
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The pieces of a line inside the image (and inside ``mask``), as end-point pairs (x, y)."""
    h, w = shape
    (x0, y0), (x1, y1) = ends
    n = int(math.hypot(x1 - x0, y1 - y0)) + 1
    xs, ys = np.linspace(x0, x1, n), np.linspace(y0, y1, n)
    xi, yi = np.rint(xs).astype(np.int64), np.rint(ys).astype(np.int64)
    inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    if mask is not None:
        inside[inside] = mask[yi[inside], xi[inside]]
    d = np.diff(np.r_[0, inside.astype(np.int8), 0])
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return [((xs[a], ys[a]), (xs[b], ys[b])) for a, b in zip(starts, stops, strict=True) if b > a]


def topology_json(graph: nx.Graph) -> dict[str, Any]:
    """networkx node-link JSON of the region graph."""
    import networkx as nx  # imported when first needed

    data: dict[str, Any] = nx.node_link_data(graph, edges="links")
    return data


def write_outputs(decomposition: Decomposition, out_dir: Path) -> dict[str, Path]:
    """Write labels.png, segments.png, layout.geojson, topology.json and overview.png into ``out_dir``.

    Images are in the input image's row order (top row = highest y).
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise DecompositionError(f"cannot create output folder {out}: {err}") from err
    paths = {
        "labels": out / "labels.png",
        "segments": out / "segments.png",
        "layout": out / "layout.geojson",
        "topology": out / "topology.json",
        "overview": out / "overview.png",
    }
    if decomposition.segments.max() > np.iinfo(np.uint16).max:
        raise DecompositionError(f"{decomposition.segments.max()} regions do not fit a 16-bit segments.png")
    Image.fromarray(np.ascontiguousarray(decomposition.labels[::-1])).save(paths["labels"])
    cv2.imwrite(str(paths["segments"]), np.ascontiguousarray(decomposition.segments[::-1].astype(np.uint16)))
    paths["layout"].write_text(json.dumps(layout_features(decomposition)))
    paths["topology"].write_text(json.dumps(topology_json(decomposition.topology)))
    Image.fromarray(overview_image(decomposition)).save(paths["overview"])
    return paths


def decompose_map_file(
    map_path: Path,
    out_dir: Path,
    *,
    resolution_m: float | None = None,
    label_overrides: Mapping[int, PlaceLabel] | None = None,
) -> Decomposition:
    """Decompose a map file and write its outputs (the ``aisle decompose`` command).

    Parameters
    ----------
    map_path : Path
        map_server YAML, or a bare PNG/PGM image (then ``resolution_m`` is required).
    out_dir : Path
        Folder for labels.png, segments.png, layout.geojson, topology.json, overview.png.
    resolution_m : float, optional
        Metres per pixel of a bare image (must agree with a YAML's if given).
    label_overrides : mapping, optional
        Place category -> label, replacing the automatic assignment.

    Raises
    ------
    DecompositionError
        Missing, unreadable or malformed map files, maps without free space, bad overrides.
    """
    occ, res, origin = read_map_file(Path(map_path), resolution_m=resolution_m)
    result = decompose(occ, resolution_m=res, origin_xy_m=origin, label_overrides=label_overrides)
    write_outputs(result, Path(out_dir))
    logger.info("decomposed %s: %d regions into %s", map_path, len(result.regions), out_dir)
    return result
