"""A layout scene (:func:`atlas.render.scene.layout_scene`) drawn with OpenCV as a PNG."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt

from atlas.render.layers import encode_png
from atlas.render.scene import (
    FONT,
    FONT_SCALE,
    KIND_STYLES,
    LEGEND_PAD_PX,
    LEGEND_ROW_PX,
    LEGEND_SWATCH_PX,
    OUTLINE,
    DrawnFeature,
    FloatArray,
    KindStyle,
    LayoutScene,
    Marker,
    Swatch,
    View,
    legend_rows,
    legend_size,
    marker_centres,
)

_SHIFT = 4
"""Fractional bits of OpenCV's fixed-point coordinates (1/16 px)."""
_ONE = 1 << _SHIFT
_COORD_LIMIT = float((1 << 30) // _ONE)


def _fixed(points: FloatArray) -> npt.NDArray[np.int32]:
    """Pixel coordinates in OpenCV's fixed point (``_SHIFT`` fractional bits), clamped far off the image."""
    return np.rint(np.clip(points, -_COORD_LIMIT, _COORD_LIMIT) * _ONE - 0.5 * _ONE).astype(np.int32)


def _marker_polygon(marker: Marker, size_px: float) -> FloatArray:
    half = size_px / 2.0
    match marker:
        case Marker.SQUARE:
            return np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
        case Marker.TRIANGLE:
            return np.array([[0.0, -half], [half, half * 0.8], [-half, half * 0.8]])
        case Marker.DIAMOND:
            return np.array([[0.0, -half], [half, 0.0], [0.0, half], [-half, 0.0]])
        case _:
            return np.zeros((0, 2))


def draw_markers(image: npt.NDArray[np.uint8], centres: FloatArray, style: KindStyle, *,
                 size_px: float | None = None) -> None:
    """Draw ``style``'s marker centred on each of ``centres`` (n, 2), pixel coordinates."""
    size = float(style.marker_px if size_px is None else size_px)
    if style.marker is Marker.DOT:
        radius = round(size / 2.0 * _ONE)
        for x, y in _fixed(centres).tolist():
            cv2.circle(image, (x, y), radius, style.colour, -1, cv2.LINE_AA, _SHIFT)
        return
    for centre in centres:
        _draw_shape_marker(image, centre, style, size)


def _draw_shape_marker(image: npt.NDArray[np.uint8], centre: FloatArray, style: KindStyle, size: float) -> None:
    outlined = style.mark_centre
    if style.marker is Marker.CROSS:
        ends = _fixed(centre + np.array([[-1, -1], [1, 1], [-1, 1], [1, -1]]) * size / 2.0)
        if outlined:
            cv2.polylines(image, [ends[:2], ends[2:]], False, OUTLINE, style.width_px + 2, cv2.LINE_AA, _SHIFT)
        cv2.polylines(image, [ends[:2], ends[2:]], False, style.colour, style.width_px, cv2.LINE_AA, _SHIFT)
    else:
        corners = _fixed(centre + _marker_polygon(style.marker, size))
        cv2.fillPoly(image, [corners], style.colour, cv2.LINE_AA, _SHIFT)
        if outlined:
            cv2.polylines(image, [corners], True, OUTLINE, 1, cv2.LINE_AA, _SHIFT)


def _fixed_px(view: View, arrays: Sequence[FloatArray]) -> list[npt.NDArray[np.int32]]:
    """Each array of map metres (n, 2) in fixed-point pixels, transformed in one go."""
    if not arrays:
        return []
    fixed = _fixed(view.to_px(np.vstack(arrays)))
    return np.split(fixed, np.cumsum([len(a) for a in arrays])[:-1])


def _draw_kind(image: npt.NDArray[np.uint8], view: View, style: KindStyle, items: Sequence[DrawnFeature]) -> None:
    shapes = [polygon for item in items for polygon in item.shapes.polygons]
    outlines = _fixed_px(view, [ring for polygon in shapes for ring in polygon])
    if outlines and style.fill_alpha > 0:
        ends = np.cumsum([len(polygon) for polygon in shapes]).tolist()
        _fill(image, [outlines[end - len(polygon):end] for polygon, end in zip(shapes, ends, strict=True)], style)
    lines = _fixed_px(view, [line for item in items for line in item.shapes.lines])
    if outlines:
        cv2.polylines(image, outlines, True, style.colour, style.width_px, cv2.LINE_AA, _SHIFT)
    if lines:
        cv2.polylines(image, lines, False, style.colour, style.width_px, cv2.LINE_AA, _SHIFT)
    centres = marker_centres(items, style)
    if centres:
        draw_markers(image, view.to_px(np.vstack(centres)), style)


def _fill(image: npt.NDArray[np.uint8], polygons: list[list[npt.NDArray[np.int32]]], style: KindStyle) -> None:
    """Fill the polygons (fixed-point rings) translucently, blending only the part of the image they cover."""
    corners = np.vstack([ring for rings in polygons for ring in rings]) >> _SHIFT
    left, top = np.clip(corners.min(axis=0) - 1, 0, None)
    right, bottom = np.minimum(corners.max(axis=0) + 2, [image.shape[1], image.shape[0]])
    if right <= left or bottom <= top:
        return
    window = image[top:bottom, left:right]
    overlay = window.copy()
    offset = -np.array([left, top]) * _ONE
    for rings in polygons:
        cv2.fillPoly(overlay, [ring + offset for ring in rings], style.colour, cv2.LINE_AA, _SHIFT)
    window[...] = cv2.addWeighted(overlay, style.fill_alpha, window, 1.0 - style.fill_alpha, 0.0)


def _draw_legend(canvas: npt.NDArray[np.uint8], scene: LayoutScene, left: int) -> None:
    for i, (role, entry) in enumerate(legend_rows(scene)):
        top = 4 + i * LEGEND_ROW_PX
        middle = np.array([left + LEGEND_PAD_PX + LEGEND_SWATCH_PX / 2.0, top + LEGEND_ROW_PX / 2.0])
        text_x = left + LEGEND_PAD_PX + (LEGEND_SWATCH_PX + 6 if role == "entry" else 0)
        if role == "scale":
            length = scene.scale_bar_m * scene.view.px_per_m
            x0, y = left + LEGEND_PAD_PX, top + LEGEND_ROW_PX // 2
            cv2.rectangle(canvas, (x0, y - 2), (round(x0 + length), y + 2), (0, 0, 0), -1)
            cv2.putText(canvas, f"{scene.scale_bar_m:g} m", (round(x0 + length) + 6, top + 13), FONT, FONT_SCALE,
                        (0, 0, 0), 1, cv2.LINE_AA)
            continue
        assert entry is not None
        if entry.style is not None:
            _draw_swatch(canvas, middle, entry.style)
        elif entry.colour is not None:
            cv2.rectangle(canvas, (round(middle[0]) - 7, top + 3), (round(middle[0]) + 7, top + 15), entry.colour, -1)
            cv2.rectangle(canvas, (round(middle[0]) - 7, top + 3), (round(middle[0]) + 7, top + 15), (90, 90, 90), 1)
        colour = (90, 90, 90) if role == "heading" else (0, 0, 0)
        cv2.putText(canvas, entry.text, (text_x, top + 13), FONT, FONT_SCALE, colour, 1, cv2.LINE_AA)


def _draw_swatch(canvas: npt.NDArray[np.uint8], middle: FloatArray, style: KindStyle) -> None:
    if style.swatch is Swatch.MARKER:
        draw_markers(canvas, middle[None], style, size_px=min(style.marker_px, LEGEND_ROW_PX - 4))
        return
    half = np.array([LEGEND_SWATCH_PX / 2.0 - 2, 6.0 if style.swatch is Swatch.FILL else 0.0])
    if style.swatch is Swatch.LINE:
        ends = _fixed(np.vstack([middle - half, middle + half]))
        cv2.polylines(canvas, [ends], False, style.colour, max(style.width_px, 2), cv2.LINE_AA, _SHIFT)
        return
    box = _fixed(np.vstack([middle - half, middle + half * [1, -1], middle + half, middle - half * [1, -1]]))
    overlay = canvas.copy()
    cv2.fillPoly(overlay, [box], style.colour, cv2.LINE_AA, _SHIFT)
    alpha = max(style.fill_alpha, 0.35)
    canvas[...] = cv2.addWeighted(overlay, alpha, canvas, 1.0 - alpha, 0.0)
    cv2.polylines(canvas, [box], True, style.colour, style.width_px, cv2.LINE_AA, _SHIFT)


def render_png(scene: LayoutScene) -> bytes:
    """The scene as PNG bytes: the map (``view.width_px`` x ``view.height_px``) with the legend to its right."""
    image = scene.base.copy()
    by_kind: dict[str, list[DrawnFeature]] = {}
    for item in scene.features:
        by_kind.setdefault(item.kind, []).append(item)
    for kind, items in by_kind.items():
        _draw_kind(image, scene.view, KIND_STYLES[kind], items)
    legend_w, legend_h = legend_size(scene)
    canvas = np.full((max(scene.view.height_px, legend_h), scene.view.width_px + legend_w, 3), 255, np.uint8)
    canvas[: scene.view.height_px, : scene.view.width_px] = image
    canvas[:, scene.view.width_px] = 200
    _draw_legend(canvas, scene, scene.view.width_px)
    return encode_png(canvas)
