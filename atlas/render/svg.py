"""A layout scene (:func:`atlas.render.scene.layout_scene`) as SVG text.

The map is drawn in map metres inside a group whose transform scales to pixels and flips y (the
map's y is up, SVG's down); the occupancy background is embedded as a base64 PNG ``<image>`` in
the pixel frame, and the legend sits to the right in pixels. Each feature carries a ``<title>``
(kind and key), which browsers show on hover.
"""

from __future__ import annotations

import base64
from collections.abc import Sequence
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from atlas.render.layers import encode_png
from atlas.render.scene import (
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
    legend_rows,
    legend_size,
    marker_centres,
)

MEDIA_TYPE = "image/svg+xml"
FONT_PX = 11


def _hex(colour: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*colour)


def _num(value: float) -> str:
    return f"{value:.3f}"


def _ring_path(ring: FloatArray, *, closed: bool) -> str:
    points = "L".join(["%.3f %.3f"] * len(ring)) % tuple(ring.ravel().tolist())
    return f"M{points}{'Z' if closed else ''}"


def _marker_path(marker: Marker, centre: FloatArray, size_m: float) -> str:
    """Path of a marker at ``centre`` (metres, y up), ``size_m`` wide."""
    half = size_m / 2.0
    offsets = {
        Marker.SQUARE: [[-half, -half], [half, -half], [half, half], [-half, half]],
        Marker.TRIANGLE: [[0.0, half], [half, -half * 0.8], [-half, -half * 0.8]],
        Marker.DIAMOND: [[0.0, half], [half, 0.0], [0.0, -half], [-half, 0.0]],
    }
    if marker is Marker.CROSS:
        ends = centre + np.array([[-half, -half], [half, half], [-half, half], [half, -half]])
        return f"{_ring_path(ends[:2], closed=False)}{_ring_path(ends[2:], closed=False)}"
    return _ring_path(centre + np.array(offsets[marker]), closed=True)


def _title(item: DrawnFeature) -> str:
    return f"<title>{escape(item.kind + ' ' + ', '.join(item.keys))}</title>"


def _kind_group(kind: str, items: Sequence[DrawnFeature], px_per_m: float) -> list[str]:
    style = KIND_STYLES[kind]
    colour, width_m = _hex(style.colour), style.width_px / px_per_m
    out = [f'<g class="kind" data-kind={quoteattr(kind)} stroke="{colour}" stroke-width="{width_m:.4g}" '
           f'stroke-linejoin="round" stroke-linecap="round">']
    for item in items:
        for polygon in item.shapes.polygons:
            path = "".join(_ring_path(ring, closed=True) for ring in polygon)
            fill = f'fill="{colour}" fill-opacity="{style.fill_alpha:g}"' if style.fill_alpha > 0 else 'fill="none"'
            out.append(f'<path d="{path}" {fill} fill-rule="evenodd">{_title(item)}</path>')
        for line in item.shapes.lines:
            out.append(f'<path d="{_ring_path(line, closed=False)}" fill="none">{_title(item)}</path>')
    out.extend(_markers(style, items, px_per_m))
    out.append("</g>")
    return out


def _markers(style: KindStyle, items: Sequence[DrawnFeature], px_per_m: float) -> list[str]:
    size_m = style.marker_px / px_per_m
    stroke = (f'stroke="{_hex(OUTLINE)}" stroke-width="{1.0 / px_per_m:.4g}"' if style.mark_centre
              else 'stroke="none"')
    out = []
    for item in items:
        for centre in marker_centres([item], style):
            if style.marker is Marker.DOT:
                out.append(f'<circle cx="{_num(centre[0])}" cy="{_num(centre[1])}" r="{size_m / 2.0:.4g}" '
                           f'fill="{_hex(style.colour)}" stroke="none">{_title(item)}</circle>')
            elif style.marker is Marker.CROSS:
                out.append(f'<path d="{_marker_path(style.marker, centre, size_m)}" fill="none">{_title(item)}</path>')
            else:
                out.append(f'<path d="{_marker_path(style.marker, centre, size_m)}" fill="{_hex(style.colour)}" '
                           f'{stroke}>{_title(item)}</path>')
    return out


def _swatch(style: KindStyle, x: float, y: float) -> str:
    """A legend swatch centred on pixel (x, y)."""
    colour = _hex(style.colour)
    half = LEGEND_SWATCH_PX / 2.0 - 2
    if style.swatch is Swatch.LINE:
        return (f'<line x1="{x - half:g}" y1="{y:g}" x2="{x + half:g}" y2="{y:g}" stroke="{colour}" '
                f'stroke-width="{max(style.width_px, 2)}"/>')
    if style.swatch is Swatch.FILL:
        return (f'<rect x="{x - half:g}" y="{y - 6:g}" width="{2 * half:g}" height="12" fill="{colour}" '
                f'fill-opacity="{max(style.fill_alpha, 0.35):g}" stroke="{colour}" stroke-width="{style.width_px}"/>')
    size = min(style.marker_px, LEGEND_ROW_PX - 4)
    centre = np.array([x, -y])
    stroke = f'stroke="{_hex(OUTLINE)}" stroke-width="1"' if style.mark_centre else 'stroke="none"'
    if style.marker is Marker.DOT:
        return f'<circle cx="{x:g}" cy="{y:g}" r="{size / 2.0:g}" fill="{colour}"/>'
    if style.marker is Marker.CROSS:
        return (f'<path transform="scale(1 -1)" d="{_marker_path(style.marker, centre, size)}" fill="none" '
                f'stroke="{colour}" stroke-width="{style.width_px}"/>')
    return f'<path transform="scale(1 -1)" d="{_marker_path(style.marker, centre, size)}" fill="{colour}" {stroke}/>'


def _legend(scene: LayoutScene) -> list[str]:
    out = [f'<g id="legend" transform="translate({scene.view.width_px} 0)" font-size="{FONT_PX}">']
    for i, (role, entry) in enumerate(legend_rows(scene)):
        top = 4 + i * LEGEND_ROW_PX
        x, y = LEGEND_PAD_PX + LEGEND_SWATCH_PX / 2.0, top + LEGEND_ROW_PX / 2.0
        text_x = LEGEND_PAD_PX + (LEGEND_SWATCH_PX + 6 if role == "entry" else 0)
        if role == "scale":
            length = scene.scale_bar_m * scene.view.px_per_m
            out.append(f'<rect class="scale-bar" x="{LEGEND_PAD_PX}" y="{y - 2:g}" width="{length:.2f}" height="4" '
                       f'fill="black"/>')
            out.append(f'<text x="{LEGEND_PAD_PX + length + 6:.2f}" y="{top + 13}">{scene.scale_bar_m:g} m</text>')
            continue
        assert entry is not None
        if entry.style is not None:
            out.append(_swatch(entry.style, x, y))
        elif entry.colour is not None:
            out.append(f'<rect x="{x - 7:g}" y="{top + 3}" width="14" height="12" fill="{_hex(entry.colour)}" '
                       f'stroke="#5a5a5a"/>')
        weight = ' font-weight="bold"' if role == "title" else ""
        fill = "#5a5a5a" if role == "heading" else "black"
        out.append(f'<text class={quoteattr(role)} x="{text_x}" y="{top + 13}" fill="{fill}"{weight}>'
                   f"{escape(entry.text)}</text>")
    out.append("</g>")
    return out


def render_svg(scene: LayoutScene) -> bytes:
    """The scene as an SVG document (UTF-8): the map, ``view.width_px`` x ``view.height_px`` px, legend to the right."""
    view = scene.view
    legend_w, legend_h = legend_size(scene)
    width, height = view.width_px + legend_w, max(view.height_px, legend_h)
    s = view.px_per_m
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="{width}" '
        f'height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif">',
        f"<title>{escape(scene.title)}</title>",
        f'<rect width="{width}" height="{height}" fill="white"/>',
        f'<defs><clipPath id="map-view"><rect width="{view.width_px}" height="{view.height_px}"/></clipPath></defs>',
        '<g clip-path="url(#map-view)">',
    ]
    if scene.has_background:
        png = base64.b64encode(encode_png(scene.base)).decode("ascii")
        out.append(f'<image id="background" x="0" y="0" width="{view.width_px}" height="{view.height_px}" '
                   f'preserveAspectRatio="none" style="image-rendering:pixelated" '
                   f'xlink:href="data:image/png;base64,{png}"/>')
    out.append(f'<g id="features" transform="matrix({s:.6g} 0 0 {-s:.6g} {-s * view.min_x_m:.3f} '
               f'{s * view.max_y_m:.3f})">')
    by_kind: dict[str, list[DrawnFeature]] = {}
    for item in scene.features:
        by_kind.setdefault(item.kind, []).append(item)
    for kind, items in by_kind.items():
        out.extend(_kind_group(kind, items, s))
    out.append("</g></g>")
    out.append(f'<line x1="{view.width_px}" y1="0" x2="{view.width_px}" y2="{height}" stroke="#c8c8c8"/>')
    out.extend(_legend(scene))
    out.append("</svg>")
    return "\n".join(out).encode()
