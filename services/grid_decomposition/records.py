"""A decomposition as map-store records: label and segment layers, features, topology."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.known_racks import footprint_mask
from services.grid_decomposition.mapfile import layout_features
from services.grid_decomposition.overview import LABEL_COLOURS
from services.grid_decomposition.pipeline import Decomposition
from shared.store import Feature, GridLayer, TopologyEdge, TopologyNode
from shared.vocabulary import REGION_KINDS, FeatureKind, LayerName, PlaceLabel

PLACE_LABELS = "place_labels"
"""``meta["encoding"]`` of the label layer: uint8 :class:`PlaceLabel` codes, ``meta["classes"][code]`` names each."""
PLACE_SEGMENTS = "place_segments"
"""``meta["encoding"]`` of the segment layer: region ids (uint16, or uint32 once an id exceeds 65535: ids are
stable across revisions and never reused, :mod:`~services.grid_decomposition.keys`), 0 where no region."""

REGION_FEATURE_KINDS: Final[dict[PlaceLabel, FeatureKind]] = {
    PlaceLabel.NONE: FeatureKind.REGION,
    PlaceLabel.CORRIDOR: FeatureKind.CORRIDOR,
    PlaceLabel.JUNCTION: FeatureKind.JUNCTION,
    PlaceLabel.STORAGE: FeatureKind.REGION,
    PlaceLabel.ROOM: FeatureKind.ROOM,
    PlaceLabel.OPEN_AREA: FeatureKind.OPEN_AREA,
    PlaceLabel.UNIDENTIFIED: FeatureKind.REGION,
}
"""Store feature kind of a region of each label; labels without a kind of their own are ``region``
features whose ``label`` property names them (``storage``, ``unidentified``)."""

FEATURE_KINDS: Final = tuple(sorted((*REGION_KINDS, FeatureKind.LINE, FeatureKind.RACK_ROW, FeatureKind.WALL)))
"""Every kind :func:`decomposition_features` returns (each key is always present)."""


def region_key(region_id: int) -> str:
    """Key of a region's feature and topology node."""
    return f"r{region_id}"


def decomposition_layers(
    decomposition: Decomposition,
    *,
    label_layer: str = LayerName.PLACE_LABELS,
    segment_layer: str = LayerName.PLACE_SEGMENTS,
    meta: Mapping[str, Any] | None = None,
) -> list[GridLayer]:
    """The label layer (uint8 :class:`PlaceLabel` codes) and the segment layer (region ids).

    Parameters
    ----------
    decomposition : Decomposition
        Its grids are in GridLayer order (row 0 = lowest y); the layers take its resolution and
        origin.
    label_layer, segment_layer : str
        Layer names.
    meta : mapping, optional
        Added to both layers' meta (e.g. the source revision).

    Returns
    -------
    [GridLayer, GridLayer]
        Labels with meta ``{"encoding": "place_labels", "classes": [...], "colours": [...]}``,
        segments with meta ``{"encoding": "place_segments", "regions": n}``.

    Raises
    ------
    DecompositionError
        A negative region id.
    """
    segments = decomposition.segments
    if segments.min(initial=0) < 0:
        raise DecompositionError(f"region id {segments.min()} is negative")
    wide = segments.max(initial=0) > np.iinfo(np.uint16).max
    extra = dict(meta or {})
    res, (ox, oy) = decomposition.resolution_m, decomposition.origin_xy_m
    labels = GridLayer(label_layer, decomposition.labels.astype(np.uint8), res, ox, oy, {
        "encoding": PLACE_LABELS,
        "classes": [label.name.lower() for label in PlaceLabel],
        "colours": [list(LABEL_COLOURS[label]) for label in PlaceLabel],
        **extra,
    })
    segs = GridLayer(segment_layer, segments.astype(np.uint32 if wide else np.uint16), res, ox, oy,
                     {"encoding": PLACE_SEGMENTS, "regions": len(decomposition.regions), **extra})
    return [labels, segs]


RACK_ROW_SOURCE = "grid_decomposition"
"""``source`` property of the rack rows the decomposition found in the occupancy grid (the pillar stage's say
``pillar_mapping``)."""


def rack_row_features(decomposition: Decomposition, *, known_racks: npt.NDArray[np.bool_] | None = None
                      ) -> list[Feature]:
    """The rack rows the decomposition found (solid racks, rows of dashes, uprights) as ``rack_row`` features.

    Polygons (the row's rectangle, map metres) keyed ``grid-row-NNN`` in order of their centres (y, then x),
    properties ``source`` (:data:`RACK_ROW_SOURCE`), ``length_m``, ``depth_m``. A row lying mostly
    (over half its cells) in ``known_racks`` (the footprints of the pillar stage's rows, the authority, on the
    decomposition's grid) is left out: that stage has it already.
    """
    rows = np.asarray(decomposition.rack_rows_px, dtype=np.float64).reshape(-1, 4, 2)
    res, origin = decomposition.resolution_m, np.asarray(decomposition.origin_xy_m)
    corners_m = origin + rows * res
    centres = corners_m.mean(axis=1)
    out: list[Feature] = []
    for k in np.lexsort((centres[:, 0], centres[:, 1])) if len(rows) else []:
        if known_racks is not None:
            own = footprint_mask([corners_m[k]], shape=decomposition.segments.shape, resolution_m=res,
                                 origin_xy_m=decomposition.origin_xy_m)
            if own.any() and np.count_nonzero(own & known_racks) > 0.5 * np.count_nonzero(own):
                continue
        sides = np.linalg.norm(np.diff(corners_m[k], axis=0, append=corners_m[k][:1]), axis=1)
        ring = [[round(float(x), 4), round(float(y), 4)] for x, y in corners_m[k]]
        out.append(Feature(FeatureKind.RACK_ROW, f"grid-row-{len(out) + 1:03d}",
                           {"type": "Polygon", "coordinates": [[*ring, ring[0]]]}, {
                               "kind": FeatureKind.RACK_ROW.value,
                               "source": RACK_ROW_SOURCE,
                               "length_m": round(float(sides.max()), 3),
                               "depth_m": round(float(sides.min()), 3),
                           }))
    return out


def decomposition_features(decomposition: Decomposition, *, known_racks: npt.NDArray[np.bool_] | None = None,
                           aisles: Mapping[int, str] | None = None) -> dict[str, list[Feature]]:
    """Regions, walls, decomposition lines and rack rows as store features, geometry in map metres.

    The geometry is that of ``layout.geojson`` (:func:`layout_features`). Regions become
    ``corridor``, ``junction``, ``room`` or ``open_area`` features, storage (pallet cells) and
    unidentified regions ``region`` features; every region has properties ``label``, ``region_id``,
    ``category`` and ``area_m2``, and the key of its topology node (:func:`region_key`). Cogent edges
    are ``wall`` features with ``label`` ``wall`` or ``door`` (a closed doorway); the lines that cut
    the map are ``line`` features (``label`` ``coarse`` or ``fine``); the rack rows found are ``rack_row``
    features (:func:`rack_row_features`, rows in ``known_racks`` left out). A region that is an aisle
    (``aisles``: region id -> ``aisle-NN``) has property ``aisle``.

    Returns
    -------
    dict
        Every kind of :data:`FEATURE_KINDS`, each with its complete (possibly empty) list.
    """
    out: dict[str, list[Feature]] = {kind: [] for kind in FEATURE_KINDS}
    out[FeatureKind.RACK_ROW] = rack_row_features(decomposition, known_racks=known_racks)
    for item in layout_features(decomposition)["features"]:
        props = item["properties"]
        kind, ident = props["kind"], int(props["id"])
        if kind == FeatureKind.REGION:
            region_kind = REGION_FEATURE_KINDS[PlaceLabel[props["label"].upper()]]
            out[region_kind].append(Feature(region_kind, region_key(ident), item["geometry"], {
                "label": props["label"],
                "region_id": ident,
                "category": int(props["category"]),
                "area_m2": float(props["area_m2"]),
                **({"aisle": aisles[ident]} if aisles and ident in aisles else {}),
            }))
        elif kind == FeatureKind.WALL:
            wall = Feature(FeatureKind.WALL, f"e{ident}", item["geometry"], {"label": props["label"]})
            out[FeatureKind.WALL].append(wall)
        else:
            out[FeatureKind.LINE].append(Feature(FeatureKind.LINE, f"l{ident}", item["geometry"], {
                "label": props["label"],
                "texture_region": int(props["category"]),
                "angle_rad": float(props["angle_rad"]),
                "support_m": float(props["support_m"]),
            }))
    return out


def decomposition_topology(decomposition: Decomposition, *, aisles: Mapping[int, str] | None = None
                           ) -> tuple[list[TopologyNode], list[TopologyEdge]]:
    """The region graph as store topology.

    Nodes are keyed :func:`region_key` (as the region features), kind = the region's label
    (``corridor``, ``storage``...), at the region's centroid (map metres; for a concave region it
    may lie outside it); attributes ``feature_kind``, ``category``, ``area_m2`` and, for a region that is an
    aisle (``aisles``: region id -> ``aisle-NN``), ``aisle``. Edges carry
    ``connection`` (connected, storage_access, door or disconnected).
    """
    graph = decomposition.topology
    nodes = [
        TopologyNode(region_key(int(n)), data["label"], float(data["x"]), float(data["y"]), {
            "feature_kind": REGION_FEATURE_KINDS[PlaceLabel[data["label"].upper()]],
            "category": int(data["category"]),
            "area_m2": float(data["area_m2"]),
            **({"aisle": aisles[int(n)]} if aisles and int(n) in aisles else {}),
        })
        for n, data in sorted(graph.nodes(data=True))
    ]
    edges = [
        TopologyEdge(region_key(int(a)), region_key(int(b)), {"connection": str(conn)})
        for a, b, conn in sorted(graph.edges(data="connection"))
    ]
    return nodes, edges
