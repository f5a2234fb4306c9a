"""The layout as a picture: occupancy as the background, place labels tinted, features by kind, a legend.

:func:`layout_scene` works out what to draw and where (a :class:`LayoutScene`, shared by both
outputs); :mod:`atlas.render.png` draws it with OpenCV and :mod:`atlas.render.svg` writes it as SVG.
The picture is north up: x to the right, y up, as the map frame.
"""

from __future__ import annotations

import enum
import functools
import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from atlas.render.layers import DEFAULT_LABEL_COLOURS, RenderError, layer_image
from shared.store import Feature, GridLayer
from shared.vocabulary import FeatureKind

log = logging.getLogger(__name__)

MIN_WIDTH_PX = 64
MAX_SIDE_PX = 4096
"""The map part of a picture is at most this many pixels on either side."""
MIN_VIEW_SIDE_M = 1.0
"""A view narrower than this is widened about its centre."""
PAD_FRACTION = 0.02
"""Margin round the map's extent when no bbox is given, as a fraction of its larger side."""
TINT_ALPHA = 0.45
"""Weight of a place label's colour over the occupancy background."""
FONT = cv2.FONT_HERSHEY_SIMPLEX
FONT_SCALE = 0.42
LEGEND_ROW_PX = 18
LEGEND_SWATCH_PX = 22
LEGEND_PAD_PX = 8
SCALE_BAR_PX = 80
"""The scale bar is the longest 1, 2 or 5 x 10^k metres no longer than this."""

RGB = tuple[int, int, int]
FloatArray = npt.NDArray[np.float64]


class Marker(enum.Enum):
    """Shape drawn at a point feature (and at the middle of a dock, gate, charger or object)."""

    DOT = "dot"
    SQUARE = "square"
    TRIANGLE = "triangle"
    DIAMOND = "diamond"
    CROSS = "cross"


class Swatch(enum.Enum):
    """How the legend shows a kind."""

    FILL = "fill"
    LINE = "line"
    MARKER = "marker"


@dataclass(frozen=True, slots=True)
class KindStyle:
    """How features of one kind are drawn.

    Parameters
    ----------
    colour : (r, g, b)
        0..255.
    width_px : int
        Line and outline width, pixels.
    fill_alpha : float
        Opacity of polygon fills, 0 (outline only) .. 1.
    marker : Marker
        Shape at points.
    marker_px : int
        Marker size (width), pixels.
    mark_centre : bool
        Also put a marker at the middle of lines and polygons (docks, gates, chargers, objects).
    swatch : Swatch
        How the legend shows the kind.
    """

    colour: RGB
    width_px: int
    fill_alpha: float
    marker: Marker
    marker_px: int
    mark_centre: bool
    swatch: Swatch


KIND_STYLES: Mapping[str, KindStyle] = {
    # places: outlines in darker shades of their place-label colours (the tint fills them)
    FeatureKind.UNIT: KindStyle((30, 60, 230), 2, 0.1, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.OBSTACLE: KindStyle((90, 60, 40), 1, 0.4, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.REGION: KindStyle((200, 130, 30), 1, 0.0, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.OPEN_AREA: KindStyle((60, 160, 180), 1, 0.0, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.ROOM: KindStyle((140, 100, 200), 1, 0.0, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.CORRIDOR: KindStyle((60, 150, 60), 1, 0.0, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.JUNCTION: KindStyle((40, 70, 200), 1, 0.0, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.LINE: KindStyle((150, 150, 150), 1, 0.0, Marker.DOT, 4, False, Swatch.LINE),
    FeatureKind.WALL: KindStyle((200, 30, 30), 2, 0.0, Marker.SQUARE, 6, False, Swatch.LINE),
    FeatureKind.DOOR: KindStyle((0, 200, 210), 3, 0.0, Marker.SQUARE, 6, False, Swatch.LINE),
    FeatureKind.RACK_ROW: KindStyle((139, 69, 19), 2, 0.25, Marker.SQUARE, 6, False, Swatch.LINE),
    FeatureKind.BIN: KindStyle((255, 140, 0), 1, 0.35, Marker.SQUARE, 6, False, Swatch.FILL),
    FeatureKind.PILLAR: KindStyle((30, 30, 30), 1, 0.0, Marker.DOT, 4, False, Swatch.MARKER),
    FeatureKind.DOCK: KindStyle((0, 150, 170), 3, 0.3, Marker.SQUARE, 12, True, Swatch.MARKER),
    FeatureKind.GATE: KindStyle((150, 0, 170), 3, 0.3, Marker.TRIANGLE, 13, True, Swatch.MARKER),
    FeatureKind.CHARGER: KindStyle((20, 150, 40), 2, 0.3, Marker.DIAMOND, 13, True, Swatch.MARKER),
    FeatureKind.LOAD_SCENE: KindStyle((120, 80, 40), 1, 0.3, Marker.SQUARE, 8, False, Swatch.MARKER),
    FeatureKind.BIN_STATE: KindStyle((255, 200, 0), 1, 0.6, Marker.DOT, 6, False, Swatch.MARKER),
    FeatureKind.OBJECT: KindStyle((220, 0, 110), 2, 0.3, Marker.CROSS, 12, True, Swatch.MARKER),
    FeatureKind.ROBOT: KindStyle((214, 39, 40), 2, 0.3, Marker.DOT, 12, True, Swatch.MARKER),
}
"""Style of every feature kind, in drawing order (first drawn first, so places lie under the rest)."""
OUTLINE: RGB = (20, 20, 20)
"""Outline of the larger markers."""
DEFAULT_KINDS = tuple(kind for kind in KIND_STYLES
                      if kind not in (FeatureKind.LINE, FeatureKind.BIN_STATE, FeatureKind.LOAD_SCENE))
"""Kinds drawn when none are asked for: all but ``line`` (the decomposition's cut lines, which clutter) and the bin
states and bay scenes (a dot on every bin)."""


class NothingToDrawError(RenderError):
    """No bbox was given and the map has neither a layer nor a feature to draw."""


class Shapes(NamedTuple):
    """A GeoJSON geometry as arrays of (x, y) metres."""

    points: list[FloatArray]
    lines: list[FloatArray]
    polygons: list[list[FloatArray]]
    """Each polygon's rings, the outer one first."""


def _xy(coordinates: Any, depth: int) -> list[FloatArray]:
    """Arrays of positions ``depth`` levels of nesting below ``coordinates`` (1: a list of positions)."""
    if depth == 1:
        array = np.asarray(coordinates, dtype=np.float64)
        if array.ndim != 2 or array.shape[1] < 2 or len(array) == 0:
            raise ValueError("not a list of positions")
        return [array[:, :2]]
    return [part for item in coordinates for part in _xy(item, depth - 1)]


def geometry_shapes(geometry: Mapping[str, Any]) -> Shapes | None:
    """The shapes of a GeoJSON geometry, or None when it is not one this can draw.

    Examples
    --------
    >>> geometry_shapes({"type": "Point", "coordinates": [1.0, 2.0]}).points[0].tolist()
    [[1.0, 2.0]]
    """
    coordinates: Any = geometry.get("coordinates")
    try:
        match geometry.get("type"):
            case "Point":
                shapes = Shapes(_xy([coordinates], 1), [], [])
            case "MultiPoint":
                shapes = Shapes(_xy(coordinates, 1), [], [])
            case "LineString":
                shapes = Shapes([], _xy(coordinates, 1), [])
            case "MultiLineString":
                shapes = Shapes([], _xy(coordinates, 2), [])
            case "Polygon":
                shapes = Shapes([], [], [_xy(coordinates, 2)])
            case "MultiPolygon":
                shapes = Shapes([], [], [_xy(polygon, 2) for polygon in coordinates])
            case _:
                return None
    except (TypeError, ValueError):
        return None
    polygons = [rings for rings in shapes.polygons if rings]
    return Shapes(shapes.points, shapes.lines, polygons) if shapes.points or shapes.lines or polygons else None


@dataclass(frozen=True, slots=True)
class View:
    """The part of the map shown and its pixel grid: pixel (0, 0) is the corner at (min_x, max_y)."""

    min_x_m: float
    min_y_m: float
    max_x_m: float
    max_y_m: float
    width_px: int
    height_px: int
    px_per_m: float

    def to_px(self, xy: FloatArray) -> FloatArray:
        """Map metres (n, 2) to continuous pixel coordinates (n, 2), y down."""
        return np.column_stack(((xy[:, 0] - self.min_x_m) * self.px_per_m, (self.max_y_m - xy[:, 1]) * self.px_per_m))


def view_for(extent: tuple[float, float, float, float], *, width_px: int) -> View:
    """The view of ``extent`` (min_x, min_y, max_x, max_y metres) ``width_px`` wide, aspect kept.

    A side shorter than :data:`MIN_VIEW_SIDE_M` is widened about its centre; a view that would be
    taller than :data:`MAX_SIDE_PX` is drawn at a smaller scale (and so narrower than ``width_px``).
    """
    if not MIN_WIDTH_PX <= width_px <= MAX_SIDE_PX:
        raise RenderError(f"width {width_px} px is outside {MIN_WIDTH_PX}..{MAX_SIDE_PX}")
    min_x, min_y, max_x, max_y = extent
    sides = []
    for low, high in ((min_x, max_x), (min_y, max_y)):
        grow = max(0.0, MIN_VIEW_SIDE_M - (high - low)) / 2.0
        sides.append((low - grow, high + grow))
    (min_x, max_x), (min_y, max_y) = sides
    scale = min(width_px / (max_x - min_x), MAX_SIDE_PX / (max_y - min_y))
    width = max(1, min(MAX_SIDE_PX, round((max_x - min_x) * scale)))
    height = max(1, min(MAX_SIDE_PX, round((max_y - min_y) * scale)))
    return View(min_x, max_y - height / scale, min_x + width / scale, max_y, width, height, scale)


def _union(boxes: Iterable[tuple[float, float, float, float]]) -> tuple[float, float, float, float] | None:
    found = list(boxes)
    if not found:
        return None
    return (min(b[0] for b in found), min(b[1] for b in found), max(b[2] for b in found), max(b[3] for b in found))


def _layer_extent(layer: GridLayer) -> tuple[float, float, float, float]:
    rows, cols = layer.data.shape
    return (layer.origin_x_m, layer.origin_y_m, layer.origin_x_m + cols * layer.resolution_m,
            layer.origin_y_m + rows * layer.resolution_m)


def _warp(layer: GridLayer, view: View, image_of: Any, *, nearest: bool, border: int) -> npt.NDArray[Any]:
    """The layer's cells in the view's pixels: crop to the view, ``image_of(crop)`` (north up), resample.

    ``image_of`` turns the cropped data (row 0 = lowest y) into an image whose row 0 is the highest y.
    Shrinking a greyscale image keeps the darkest cell of each block of cells a pixel or more wide, so thin
    walls stay visible.
    """
    data, res = layer.data, layer.resolution_m
    rows, cols = data.shape
    c0 = int(np.clip(math.floor((view.min_x_m - layer.origin_x_m) / res) - 1, 0, cols))
    c1 = int(np.clip(math.ceil((view.max_x_m - layer.origin_x_m) / res) + 1, 0, cols))
    r0 = int(np.clip(math.floor((view.min_y_m - layer.origin_y_m) / res) - 1, 0, rows))
    r1 = int(np.clip(math.ceil((view.max_y_m - layer.origin_y_m) / res) + 1, 0, rows))
    if c1 <= c0 or r1 <= r0:
        return np.full((view.height_px, view.width_px), border, dtype=np.uint8)
    image = np.ascontiguousarray(image_of(data[r0:r1, c0:c1]))
    cell_px = res * view.px_per_m
    if not nearest and cell_px < 1.0:
        pool = math.ceil(1.0 / cell_px)
        image, cell_px = _min_pool(image, pool, border), cell_px * pool
    left = (layer.origin_x_m + c0 * res - view.min_x_m) * view.px_per_m
    top = (view.max_y_m - layer.origin_y_m - r1 * res) * view.px_per_m
    matrix = np.array([[cell_px, 0.0, left + 0.5 * cell_px - 0.5], [0.0, cell_px, top + 0.5 * cell_px - 0.5]])
    return np.asarray(cv2.warpAffine(image, matrix, (view.width_px, view.height_px), flags=cv2.INTER_NEAREST,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=border))


def _min_pool(image: npt.NDArray[np.uint8], size: int, fill: int) -> npt.NDArray[np.uint8]:
    """The darkest value of each ``size`` x ``size`` block, anchored at the top-left (padded with ``fill``)."""
    rows, cols = -(-image.shape[0] // size) * size, -(-image.shape[1] // size) * size
    padded = np.full((rows, cols), fill, dtype=image.dtype)
    padded[: image.shape[0], : image.shape[1]] = image
    return np.ascontiguousarray(padded.reshape(rows // size, size, cols // size, size).min(axis=(1, 3)))


def _label_palette(layer: GridLayer) -> tuple[list[str], npt.NDArray[np.uint8]]:
    names = layer.meta.get("classes")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise RenderError(f"layer {layer.name!r} needs meta['classes'], a list of class names by code")
    colours = layer.meta.get("colours")
    if colours is None:
        default = [(255, 255, 255)] + [DEFAULT_LABEL_COLOURS[i % len(DEFAULT_LABEL_COLOURS)]
                                       for i in range(len(names) - 1)]
        return names, np.array(default, dtype=np.uint8)
    table = np.asarray(colours, dtype=object)
    if table.shape != (len(names), 3) or not all(isinstance(v, int) and 0 <= v <= 255 for v in table.ravel()):
        raise RenderError(f"layer {layer.name!r}: meta['colours'] must give [r, g, b] (0..255) for each class")
    return names, table.astype(np.uint8)


def _occupancy_image(data: npt.NDArray[Any]) -> npt.NDArray[np.uint8]:
    if data.dtype != np.int8:
        return layer_image(data)
    values = np.arange(-128, 128, dtype=np.int8)
    lut = np.empty(256, dtype=np.uint8)
    lut[values.view(np.uint8)] = layer_image(values.reshape(-1, 1))[::-1, 0]
    return np.ascontiguousarray(lut[data[::-1].view(np.uint8)])


@dataclass(frozen=True, slots=True)
class LegendEntry:
    """One row of the legend: a feature kind (with its style) or a place label (with its tint colour)."""

    text: str
    style: KindStyle | None = None
    colour: RGB | None = None


@dataclass(frozen=True, slots=True)
class DrawnFeature:
    """Features of one kind that share one geometry (e.g. the bins on the levels of one bay)."""

    kind: str
    keys: tuple[str, ...]
    shapes: Shapes


@dataclass(frozen=True, slots=True)
class LayoutScene:
    """Everything a picture shows, in the view's pixels and in map metres.

    ``base`` is the background raster (occupancy grey, place tint; white where there is no layer),
    ``has_background`` whether any layer was drawn into it. ``features`` come in drawing order.
    """

    view: View
    base: npt.NDArray[np.uint8]
    has_background: bool
    features: list[DrawnFeature]
    title: str
    kinds: list[LegendEntry] = field(default_factory=list)
    places: list[LegendEntry] = field(default_factory=list)

    @property
    def scale_bar_m(self) -> float:
        """Length of the scale bar, metres: 1, 2 or 5 x 10^k, at most :data:`SCALE_BAR_PX` long."""
        longest = SCALE_BAR_PX / self.view.px_per_m
        power = 10.0 ** math.floor(math.log10(longest))
        return max(step * power for step in (1.0, 2.0, 5.0) if step * power <= longest)


def _tint(base: npt.NDArray[np.uint8], labels: GridLayer, view: View) -> list[LegendEntry]:
    """Blend place-label colours into ``base`` (RGB, in place); the legend rows of the labels shown."""
    names, palette = _label_palette(labels)
    if labels.data.dtype != np.uint8:
        raise RenderError(f"layer {labels.name!r} holds {labels.data.dtype.name}, not uint8 label codes")
    codes = _warp(labels, view, lambda crop: crop[::-1], nearest=True, border=0)
    shown = np.flatnonzero(np.bincount(codes.ravel(), minlength=256)).tolist()
    if shown[-1] >= len(names):
        raise RenderError(f"layer {labels.name!r} has codes up to {shown[-1]} but names {len(names)} classes")
    table = np.zeros((256, 1, 3), np.uint8)
    table[: len(names), 0] = palette
    colours = cv2.LUT(cv2.cvtColor(codes, cv2.COLOR_GRAY2RGB), table)
    blended = cv2.addWeighted(base, 1.0 - TINT_ALPHA, colours, TINT_ALPHA, 0.0)
    np.copyto(base, blended, where=(codes > 0)[:, :, None])
    entries = []
    for code in shown:
        if code:
            red, green, blue = (int(v) for v in palette[code])
            entries.append(LegendEntry(names[code], colour=(red, green, blue)))
    return entries


def layout_scene(
    features: Sequence[Feature],
    *,
    occupancy: GridLayer | None,
    place_labels: GridLayer | None,
    bbox: tuple[float, float, float, float] | None,
    width_px: int,
    title: str,
) -> LayoutScene:
    """What a layout picture shows.

    Parameters
    ----------
    features : sequence of Feature
        The features to draw (already filtered by kind and bbox); kinds are drawn in
        :data:`KIND_STYLES` order, features of a kind sharing one geometry once.
    occupancy : GridLayer, optional
        Background: an occupancy layer (int8, drawn as map_saver would) or any numeric layer (grey).
    place_labels : GridLayer, optional
        A label layer (``meta['classes']``, optional ``meta['colours']``) tinting the background;
        left out, with a warning in the log, when its meta cannot be drawn.
    bbox : (min_x, min_y, max_x, max_y), optional
        Area shown, metres; default: the layers' and features' extent with a small margin.
    width_px : int
        Width of the map part of the picture, pixels (the legend is to its right).
    title : str
        First line of the legend (e.g. map name and revision).

    Raises
    ------
    NothingToDrawError
        No ``bbox`` and nothing to draw.
    RenderError
        ``width_px`` out of range.
    """
    drawn, counts, points = _drawn_features(features)
    layers = [layer for layer in (occupancy, place_labels) if layer is not None]
    extent = bbox
    if extent is None:
        boxes = [_layer_extent(layer) for layer in layers]
        if len(points):
            boxes.append((*points.min(axis=0).tolist(), *points.max(axis=0).tolist()))
        extent = _union(boxes)
        if extent is None:
            raise NothingToDrawError("the map has no layer and no feature to draw yet")
        pad = PAD_FRACTION * max(extent[2] - extent[0], extent[3] - extent[1])
        extent = (extent[0] - pad, extent[1] - pad, extent[2] + pad, extent[3] + pad)
    view = view_for(extent, width_px=width_px)
    grey = (np.full((view.height_px, view.width_px), 255, np.uint8) if occupancy is None
            else _warp(occupancy, view, _occupancy_image, nearest=False, border=255))
    base = np.ascontiguousarray(np.repeat(grey[:, :, None], 3, axis=2))
    places: list[LegendEntry] = []
    if place_labels is not None:
        try:
            places = _tint(base, place_labels, view)
        except RenderError as err:
            log.warning("layout picture drawn without the place tint: %s", err)
    kinds = [LegendEntry(f"{kind} ({counts[kind]})", style=KIND_STYLES[kind]) for kind in KIND_STYLES
             if kind in counts]
    return LayoutScene(view, base, bool(layers), drawn, title, kinds, places)


def _drawn_features(features: Sequence[Feature]) -> tuple[list[DrawnFeature], dict[str, int], FloatArray]:
    """Features in drawing order, those of a kind with the same geometry merged; the count per kind; every
    vertex (n, 2)."""
    drawn: dict[tuple[str, bytes], DrawnFeature] = {}
    counts: dict[str, int] = {}
    arrays: list[FloatArray] = []
    order = {kind: i for i, kind in enumerate(KIND_STYLES)}
    for feature in sorted(features, key=lambda f: order[f.kind]):
        shapes = geometry_shapes(feature.geometry)
        if shapes is None:
            log.warning("feature %s/%s has a geometry this cannot draw; left out", feature.kind, feature.key)
            continue
        counts[feature.kind] = counts.get(feature.kind, 0) + 1
        parts = [*shapes.points, *shapes.lines, *(ring for polygon in shapes.polygons for ring in polygon)]
        arrays.extend(parts)
        layout = f"{len(shapes.points)},{len(shapes.lines)},{[len(p) for p in shapes.polygons]}|".encode()
        same = (feature.kind, layout + b"|".join(a.tobytes() for a in parts))
        found = drawn.get(same)
        drawn[same] = DrawnFeature(feature.kind, (*found.keys, feature.key) if found else (feature.key,), shapes)
    return list(drawn.values()), counts, np.vstack(arrays) if arrays else np.zeros((0, 2))


def marker_centres(items: Sequence[DrawnFeature], style: KindStyle) -> list[FloatArray]:
    """Where markers go (metres): every point, and the middle of each other geometry if the style marks it."""
    centres = [point for item in items for array in item.shapes.points for point in array]
    if style.mark_centre:
        for item in items:
            parts = [*item.shapes.lines, *(polygon[0] for polygon in item.shapes.polygons)]
            if parts:
                stacked = np.vstack(parts)
                centres.append((stacked.min(axis=0) + stacked.max(axis=0)) / 2.0)
    return centres


@functools.lru_cache(maxsize=256)
def _char_px(char: str) -> int:
    return int(cv2.getTextSize(char, FONT, FONT_SCALE, 1)[0][0])


def text_px(text: str) -> int:
    """Width of ``text`` in the legend font, pixels (a little more than OpenCV draws: glyph advances summed)."""
    return sum(_char_px(char) for char in text)


def legend_size(scene: LayoutScene) -> tuple[int, int]:
    """(width, height) of the legend panel, pixels."""
    texts = [scene.title, "features", "places", *(e.text for e in (*scene.kinds, *scene.places))]
    widest = max(text_px(text) for text in texts)
    rows = len(legend_rows(scene))
    return LEGEND_PAD_PX * 2 + max(widest + LEGEND_SWATCH_PX + 6, SCALE_BAR_PX + 50), rows * LEGEND_ROW_PX + 10


def legend_rows(scene: LayoutScene) -> list[tuple[str, LegendEntry | None]]:
    """The legend's rows top to bottom: ("title" | "heading" | "entry", entry), then ("scale", None)."""
    rows: list[tuple[str, LegendEntry | None]] = [("title", LegendEntry(scene.title))]
    for heading, entries in (("features", scene.kinds), ("places", scene.places)):
        if entries:
            rows.append(("heading", LegendEntry(heading)))
            rows.extend(("entry", entry) for entry in entries)
    rows.append(("scale", None))
    return rows
