"""Polygonal cell decomposition of the plane by lines: vertices, edges, faces and the dual graph."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.radiogram import Line


@dataclass(frozen=True)
class LineGroup:
    """Lines that decompose one texture region (``mask`` True inside it; ``None`` = whole map)."""

    lines: tuple[Line, ...]
    mask: npt.NDArray[np.bool_] | None


@dataclass(frozen=True)
class Subdivision:
    """A raster planar subdivision ``S = (Vertices, Edges, Faces)`` and its dual adjacency graph.

    Faces are the 4-connected cells of the plane minus the (1 px, 8-connected) lines; an edge is
    the run of line pixels between two faces (its dual link joins their nodes).

    Attributes
    ----------
    face_image : (H, W) int32
        Face id per pixel, 1..n_faces; 0 on line pixels.
    n_faces : int
    vertices_px : (V, 2) float64
        Line intersections inside their regions, (x = column, y = row).
    edge_faces : (E, 2) int64
        The two faces ``N(e)`` of each edge, ascending, ids 1..n_faces.
    edge_pixels : (P,) int64
        Flat pixel indices of all edges, grouped by edge.
    edge_starts : (E + 1,) int64
        Edge ``e`` owns ``edge_pixels[edge_starts[e]:edge_starts[e + 1]]``.
    edge_ends_px : (E, 2, 2) float64
        The two end points of each edge, (x, y) pixels.
    line_image : (H, W) bool
        The decomposition lines as drawn.
    """

    face_image: npt.NDArray[np.int32]
    n_faces: int
    vertices_px: npt.NDArray[np.float64]
    edge_faces: npt.NDArray[np.int64]
    edge_pixels: npt.NDArray[np.int64]
    edge_starts: npt.NDArray[np.int64]
    edge_ends_px: npt.NDArray[np.float64]
    line_image: npt.NDArray[np.bool_]

    @property
    def n_edges(self) -> int:
        """Number of edges (and of links of the adjacency graph)."""
        return int(self.edge_faces.shape[0])


def line_endpoints(line: Line, shape: tuple[int, int]) -> tuple[tuple[int, int], tuple[int, int]]:
    """Two points, (x, y) integer pixels, of ``line`` far enough apart to span an image of ``shape``."""
    c, s = math.cos(line.angle_rad), math.sin(line.angle_rad)
    foot = (-s * line.offset_px, c * line.offset_px)
    reach = 2.0 * math.hypot(*shape) + abs(line.offset_px)
    p0 = (round(foot[0] - reach * c), round(foot[1] - reach * s))
    p1 = (round(foot[0] + reach * c), round(foot[1] + reach * s))
    return p0, p1


def draw_lines(groups: Sequence[LineGroup], shape: tuple[int, int]) -> npt.NDArray[np.bool_]:
    """Raster of the lines of every group, clipped to its mask, plus the borders between masks."""
    canvas = np.zeros(shape, dtype=np.uint8)
    for group in groups:
        layer = np.zeros(shape, dtype=np.uint8)
        for line in group.lines:
            p0, p1 = line_endpoints(line, shape)
            cv2.line(layer, p0, p1, 1, 1, cv2.LINE_8)
        if group.mask is not None:
            layer &= group.mask.astype(np.uint8)
            inner = np.asarray(cv2.erode(group.mask.astype(np.uint8), np.ones((3, 3), np.uint8)), dtype=bool)
            layer |= (group.mask & ~inner).astype(np.uint8)
        canvas |= layer
    return canvas.astype(bool)


def _vertices(groups: Sequence[LineGroup], shape: tuple[int, int]) -> npt.NDArray[np.float64]:
    points: list[npt.NDArray[np.float64]] = []
    for group in groups:
        if len(group.lines) < 2:
            continue
        a = np.array([ln.angle_rad for ln in group.lines])
        b = np.array([ln.offset_px for ln in group.lines])
        n = np.stack([-np.sin(a), np.cos(a)], axis=1)
        i, j = np.triu_indices(a.size, 1)
        det = n[i, 0] * n[j, 1] - n[i, 1] * n[j, 0]
        ok = np.abs(det) > 1e-6
        i, j, det = i[ok], j[ok], det[ok]
        x = (b[i] * n[j, 1] - b[j] * n[i, 1]) / det
        y = (n[i, 0] * b[j] - n[j, 0] * b[i]) / det
        inside = (x >= 0) & (x < shape[1]) & (y >= 0) & (y < shape[0])
        x, y = x[inside], y[inside]
        if group.mask is not None:
            keep = group.mask[y.astype(np.int64), x.astype(np.int64)]
            x, y = x[keep], y[keep]
        points.append(np.stack([x, y], axis=1))
    return np.concatenate(points) if points else np.zeros((0, 2))


def subdivide(
    groups: Sequence[LineGroup],
    shape: tuple[int, int],
    *,
    domain: npt.NDArray[np.bool_] | None = None,
    cuts: npt.NDArray[np.bool_] | None = None,
) -> Subdivision:
    """Decompose an image of ``shape`` (rows, cols) into polygonal faces by the lines of ``groups``.

    Parameters
    ----------
    groups : sequence of LineGroup
        Lines per texture region; a region's lines stop at its mask, and region borders are lines.
    shape : (H, W)
        Image size in pixels.
    domain : (H, W) bool, optional
        Pixels that may belong to a face. With the free space as domain, each polygonal cell is
        split into its connected free parts, so a cell cut by a curved or oblique wall yields one
        face per side and walls separate faces even where no line follows them.
    cuts : (H, W) bool, optional
        Further line pixels (the outlines of racks found from their dashes).

    Returns
    -------
    Subdivision
        Faces, edges (with their two faces, pixels and end points) and line vertices.
    """
    w = shape[1]
    line_image = draw_lines(groups, shape)
    if cuts is not None:
        line_image |= cuts
    inside = ~line_image if domain is None else ~line_image & domain
    n_labels, labels = cv2.connectedComponents(inside.astype(np.uint8), connectivity=4, ltype=cv2.CV_32S)
    face_image = np.asarray(labels, dtype=np.int32)
    # the 4 neighbours of every line pixel (0 off the image), by flat index into the face image: an index
    # past the image's edge is clipped and its neighbour set to 0 (no framed copy of the whole image)
    flat = face_image.ravel()
    idx = np.flatnonzero(line_image)
    r, c = np.divmod(idx, w)
    nb = np.empty((4, idx.size), dtype=np.int64)
    off_image = (r == 0, r == shape[0] - 1, c == 0, c == w - 1)
    for row, offset, off in zip(nb, (-w, w, -1, 1), off_image, strict=True):
        row[:] = np.take(flat, idx + offset, mode="clip")
        row[off] = 0
    keys: list[npt.NDArray[np.int64]] = []
    pix: list[npt.NDArray[np.int64]] = []
    n_labels64 = np.int64(n_labels)
    for i in range(4):
        for j in range(i + 1, 4):
            a, b = nb[i], nb[j]
            ok = (a > 0) & (b > 0) & (a != b)
            lo, hi = np.minimum(a[ok], b[ok]), np.maximum(a[ok], b[ok])
            keys.append(lo * n_labels64 + hi)
            pix.append(idx[ok])
    key = np.concatenate(keys) if keys else np.zeros(0, np.int64)
    pixel = np.concatenate(pix) if pix else np.zeros(0, np.int64)
    both = _distinct_pairs(key, pixel, n_labels64 * n_labels64, np.int64(line_image.size))
    # both is sorted by face pair: each pair's run of pixels is one edge candidate
    new_key = np.ones(both.shape[0], dtype=bool)
    new_key[1:] = both[1:, 0] != both[:-1, 0]
    ukeys = both[new_key, 0]
    inverse = np.cumsum(new_key) - 1
    counts = np.diff(np.append(np.flatnonzero(new_key), both.shape[0]))
    keep_edge = counts >= 2
    remap = np.cumsum(keep_edge) - 1
    sel = keep_edge[inverse]
    edge_of_pixel = remap[inverse[sel]]
    pixels = both[sel, 1]
    order = np.argsort(edge_of_pixel, kind="stable")
    edge_of_pixel, pixels = edge_of_pixel[order], pixels[order]
    n_edges = int(keep_edge.sum())
    starts = np.zeros(n_edges + 1, dtype=np.int64)
    np.cumsum(np.bincount(edge_of_pixel, minlength=n_edges), out=starts[1:])
    ukeys = ukeys[keep_edge]
    edge_faces = np.stack([ukeys // n_labels64, ukeys % n_labels64], axis=1)
    ends = _edge_ends(pixels, edge_of_pixel, n_edges, w)
    return Subdivision(
        face_image=face_image,
        n_faces=n_labels - 1,
        vertices_px=_vertices(groups, shape),
        edge_faces=edge_faces,
        edge_pixels=pixels,
        edge_starts=starts,
        edge_ends_px=ends,
        line_image=line_image,
    )


def _distinct_pairs(
    key: npt.NDArray[np.int64], pixel: npt.NDArray[np.int64], n_keys: np.int64, n_pixels: np.int64
) -> npt.NDArray[np.int64]:
    """(K, 2) distinct (key, pixel) rows in lexicographic order, as ``np.unique(..., axis=0)`` gives them.

    Keys below ``n_keys`` and pixels below ``n_pixels`` are sorted as one number when it fits in 64 bits.
    """
    if key.size == 0:
        return np.zeros((0, 2), np.int64)
    if int(n_keys) * int(n_pixels) >= 2**63:
        out: npt.NDArray[np.int64] = np.unique(np.stack([key, pixel], axis=1), axis=0)
        return out
    code = np.sort(key * n_pixels + pixel)
    keep = np.ones(code.size, dtype=bool)
    keep[1:] = code[1:] != code[:-1]
    code = code[keep]
    return np.stack([code // n_pixels, code % n_pixels], axis=1)


def _edge_ends(
    pixels: npt.NDArray[np.int64], edge: npt.NDArray[np.int64], n_edges: int, width: int
) -> npt.NDArray[np.float64]:
    """Extreme pixels of each edge along its principal axis, (E, 2, 2) as (x, y)."""
    if n_edges == 0:
        return np.zeros((0, 2, 2))
    y, x = np.divmod(pixels, width)
    x, y = x.astype(np.float64), y.astype(np.float64)
    n = np.bincount(edge, minlength=n_edges).astype(np.float64)
    mx = np.bincount(edge, x, n_edges) / n
    my = np.bincount(edge, y, n_edges) / n
    dx, dy = x - mx[edge], y - my[edge]
    sxx = np.bincount(edge, dx * dx, n_edges)
    syy = np.bincount(edge, dy * dy, n_edges)
    sxy = np.bincount(edge, dx * dy, n_edges)
    theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    t = dx * np.cos(theta[edge]) + dy * np.sin(theta[edge])
    tmin = np.full(n_edges, np.inf)
    tmax = np.full(n_edges, -np.inf)
    np.minimum.at(tmin, edge, t)
    np.maximum.at(tmax, edge, t)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack(
        [np.stack([mx + tmin * c, my + tmin * s], axis=1), np.stack([mx + tmax * c, my + tmax * s], axis=1)],
        axis=1,
    )
