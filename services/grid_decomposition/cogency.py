"""Occupancy of faces and edges, wall evidence along lines with doorway closing, edge cogency."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import label_counts
from services.grid_decomposition.doorways import widens
from services.grid_decomposition.subdivision import LineGroup, Subdivision, line_endpoints

DOOR_MIN_PX = 5


class EdgeCogency(NamedTuple):
    """Per-face and per-edge occupancy and the cogency of edges (paper B, section II-D).

    Attributes
    ----------
    face_occupancy : (F + 1,) float64
        ``O(f)``: mean occupancy (occupied and unknown = 1, free = 0) of each face; index 0 unused.
    face_free_px : (F + 1,) int64
        Free pixels per face.
    edge_occupancy : (E,) float64
        ``O(e)``: fraction of the edge's pixels on wall evidence (doorways closed).
    edge_door_px : (E,) int64
        Pixels of the edge on a closed doorway gap.
    cogent : (E,) bool
        ``C(e) = |O(f1) - O(f2)| > t1 or O(e) > t2``; the dual link is connected where False.
    """

    face_occupancy: npt.NDArray[np.float64]
    face_free_px: npt.NDArray[np.int64]
    edge_occupancy: npt.NDArray[np.float64]
    edge_door_px: npt.NDArray[np.int64]
    cogent: npt.NDArray[np.bool_]

    @property
    def door(self) -> npt.NDArray[np.bool_]:
        """(E,) bool: cogent edges holding a closed doorway of at least ``DOOR_MIN_PX`` pixels."""
        return self.cogent & (self.edge_door_px >= DOOR_MIN_PX)


def _runs(profile: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Start and end (exclusive) of the True runs of a 1-D mask."""
    d = np.diff(np.r_[0, profile.astype(np.int8), 0])
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def close_doorways(
    profile: npt.NDArray[np.bool_],
    *,
    min_wall_px: int,
    max_door_px: int,
    posts: npt.NDArray[np.bool_] | None = None,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Wall runs of a 1-D occupancy profile and the doorway-sized gaps between them.

    Runs shorter than ``min_wall_px`` (furniture legs, rack uprights) are not walls; gaps of at
    most ``max_door_px`` between two wall runs are candidate doorways. With ``posts`` (small
    obstacles on the line, no wall runs), a wider gap of at most ``2 * max_door_px`` is one too
    when posts in it leave no free stretch wider than ``max_door_px``: two doors side by side
    with a post or door frame between them (a real map draws the post as a speck, no wall).

    Returns
    -------
    wall : (N,) bool
        The wall runs.
    gap_start, gap_end : (G,) int64
        Candidate doorways ``[gap_start, gap_end)``.
    """
    starts, ends = _runs(profile)
    long = (ends - starts) >= min_wall_px
    starts, ends = starts[long], ends[long]
    wall = np.zeros(profile.size, dtype=bool)
    if starts.size == 0:
        return wall, np.zeros(0, np.int64), np.zeros(0, np.int64)
    cover = np.zeros(profile.size + 1, dtype=np.int64)
    np.add.at(cover, starts, 1)
    np.add.at(cover, ends, -1)
    wall[:] = np.cumsum(cover)[:-1] > 0
    gaps = starts[1:] - ends[:-1]
    small = gaps <= max_door_px
    if posts is not None:
        for i in np.flatnonzero(~small & (gaps <= 2 * max_door_px)):
            free_starts, free_ends = _runs(~posts[ends[i] : starts[i + 1]])
            small[i] = free_starts.size > 1 and int((free_ends - free_starts).max()) <= max_door_px
    return wall, ends[:-1][small].astype(np.int64), starts[1:][small].astype(np.int64)


def wall_evidence(
    occupied: npt.NDArray[np.bool_],
    groups: Sequence[LineGroup],
    *,
    tolerance_px: int,
    min_wall_px: int,
    max_door_px: int,
    widening_px: int,
    max_depth_px: int,
    posts: npt.NDArray[np.bool_] | None = None,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Rasters of wall evidence and closed doorways along every line.

    Along each line the wall mask (dilated by ``tolerance_px``, so slightly crooked walls still
    sit on their line) is read as a 1-D profile; doorway-sized gaps between wall runs
    (:func:`close_doorways`) are closed when the free space behind them widens by at least
    ``widening_px`` on both sides within ``max_depth_px`` of the line (a doorway between rooms);
    a gap that stays as narrow on one side is a corridor or a passage between blocks, left open.

    Parameters
    ----------
    occupied : (H, W) bool
        Walls: occupied and unknown cells without furniture.
    groups : sequence of LineGroup
    tolerance_px, min_wall_px, max_door_px, widening_px, max_depth_px : int
        Pixels.
    posts : (H, W) bool, optional
        Free-standing obstacles (furniture, specks): posts between doors (:func:`close_doorways`).

    Returns
    -------
    wall, door : (H, W) bool
        Line pixels (dilated by one pixel) lying on wall evidence, and those on a closed doorway.
    """
    h, w = occupied.shape
    k = 2 * tolerance_px + 1
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    near = cv2.dilate(occupied.astype(np.uint8), disk) > 0
    near_post = None if posts is None else cv2.dilate(posts.astype(np.uint8), disk) > 0
    wall = np.zeros((h, w), dtype=bool)
    door = np.zeros((h, w), dtype=bool)
    gaps: list[tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]] = []
    for group in groups:
        for line in group.lines:
            (x0, y0), (x1, y1) = line_endpoints(line, (h, w))
            n = int(math.hypot(x1 - x0, y1 - y0)) + 1
            xs = np.rint(np.linspace(x0, x1, n)).astype(np.int64)
            ys = np.rint(np.linspace(y0, y1, n)).astype(np.int64)
            inside = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
            xs, ys = xs[inside], ys[inside]
            if group.mask is not None:
                keep = group.mask[ys, xs]
                xs, ys = xs[keep], ys[keep]
            if xs.size == 0:
                continue
            on_wall, g0, g1 = close_doorways(
                near[ys, xs], min_wall_px=min_wall_px, max_door_px=max_door_px,
                posts=None if near_post is None else near_post[ys, xs],
            )
            wall[ys[on_wall], xs[on_wall]] = True
            if g0.size:
                gaps.append((xs, ys, g0, g1))
    if gaps:  # every line's gaps in one call: each gap's answer is its own
        ends = np.concatenate([
            np.stack([np.stack([xs[g0], ys[g0]], axis=1), np.stack([xs[g1 - 1], ys[g1 - 1]], axis=1)], axis=1)
            for xs, ys, g0, g1 in gaps
        ]).astype(np.float64)
        doorway = widens(
            near,
            ends,
            widening_px=widening_px,
            max_depth_px=max_depth_px + tolerance_px,
            depth_step_px=max(1, max_depth_px // 4),
        )
        first = 0
        for xs, ys, g0, g1 in gaps:
            opened = doorway[first : first + g0.size]
            first += g0.size
            for a, b in zip(g0[opened], g1[opened], strict=True):
                wall[ys[a:b], xs[a:b]] = True
                door[ys[a:b], xs[a:b]] = True
    kernel = np.ones((3, 3), np.uint8)
    solid = cv2.dilate((wall & ~door).astype(np.uint8), kernel) > 0
    wall = cv2.dilate(wall.astype(np.uint8), kernel) > 0
    door = (cv2.dilate(door.astype(np.uint8), kernel) > 0) & ~(solid & occupied)
    return wall, door


def edge_cogency(
    sub: Subdivision,
    occupancy01: npt.NDArray[np.float64],
    free: npt.NDArray[np.bool_],
    wall: npt.NDArray[np.bool_],
    door: npt.NDArray[np.bool_],
    *,
    face_disparity_threshold: float = 0.5,
    edge_occupancy_threshold: float = 0.5,
) -> EdgeCogency:
    """Occupancy of faces and edges and the cogency of every edge.

    Parameters
    ----------
    sub : Subdivision
    occupancy01 : (H, W) float64
        Occupancy in [0, 1] (unknown counted as 1).
    free : (H, W) bool
    wall, door : (H, W) bool
        From :func:`wall_evidence`.
    face_disparity_threshold, edge_occupancy_threshold : float
        ``t1`` and ``t2`` of paper B.
    """
    faces = sub.face_image.ravel()
    n = sub.n_faces + 1
    count, free_px = label_counts(sub.face_image, n, free)
    area = count.astype(np.float64)
    # a face's sum over its pixels in raster order, as bincount adds them, without the zeros (adding 0.0
    # changes no sum: the same bits); face 0 (lines and obstacles) is set to 1 below
    weights = occupancy01.ravel()
    some = np.flatnonzero((faces > 0) & (weights != 0))
    occ_sum = np.bincount(faces[some], weights=weights[some], minlength=n)
    face_occ = np.divide(occ_sum, area, out=np.ones(n), where=area > 0)
    free_px[0] = 0
    face_occ[0] = 1.0
    e_n = np.diff(sub.edge_starts)
    edge_index = np.repeat(np.arange(sub.n_edges), e_n)
    e_wall = np.bincount(edge_index, weights=wall.ravel()[sub.edge_pixels], minlength=sub.n_edges)
    e_door = np.bincount(edge_index, weights=door.ravel()[sub.edge_pixels], minlength=sub.n_edges)
    safe = np.maximum(e_n, 1)
    edge_occ = e_wall / safe
    a, b = sub.edge_faces[:, 0], sub.edge_faces[:, 1]
    disparity = np.abs(face_occ[a] - face_occ[b])
    cogent = (disparity > face_disparity_threshold) | (edge_occ > edge_occupancy_threshold)
    return EdgeCogency(face_occ, free_px, edge_occ, e_door.astype(np.int64), cogent)
