"""The working grid: the map turned so that its dominant walls run along rows and columns.

Units are axis-aligned rectangles of cells (:mod:`~services.floor_plan.world`); a map whose walls run at
an angle is explained in a grid turned by that angle (its dominant wall direction, :func:`dominant_angle`)
and the units are turned back into the map. Points use OpenCV's convention inside this module
(x = column, y = row, cell centres at integers); the public helpers take cell-corner coordinates (row,
column) as the rest of the stage does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeVar

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan.likelihood import CellClass
from services.floor_plan.world import Rect, World

_Cell = TypeVar("_Cell", np.uint8, np.float32)


@dataclass(frozen=True)
class Frame:
    """A map grid turned by ``-angle_rad`` (so lines at ``angle_rad`` run along rows) into a grid of ``shape``.

    ``matrix`` (2 x 3) maps map cell centres (x = column, y = row) to working cell centres. The map's
    origin and resolution let a world move between the frames of two revisions of a growing map.
    """

    angle_rad: float
    map_shape: tuple[int, int]
    shape: tuple[int, int]
    matrix: npt.NDArray[np.float64]
    origin_xy_m: tuple[float, float]
    resolution_m: float

    @property
    def turned(self) -> bool:
        return self.angle_rad != 0.0


def make_frame(map_shape: tuple[int, int], *, angle_rad: float, origin_xy_m: tuple[float, float] = (0.0, 0.0),
               resolution_m: float = 1.0) -> Frame:
    """The frame that turns a map of ``map_shape`` cells by ``-angle_rad`` (0: the map itself)."""
    h, w = map_shape
    if angle_rad == 0.0:
        return Frame(0.0, (h, w), (h, w), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), origin_xy_m, resolution_m)
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    turn = np.array([[c, s], [-s, c]])  # rotation by -angle in (x, y)
    corners = turn @ np.array([[-0.5, w - 0.5, w - 0.5, -0.5], [-0.5, -0.5, h - 0.5, h - 0.5]])
    low = corners.min(axis=1)
    size = np.ceil(corners.max(axis=1) - low).astype(int)
    matrix = np.hstack([turn, (-low - 0.5)[:, None]])
    return Frame(angle_rad, (h, w), (int(size[1]), int(size[0])), matrix, origin_xy_m, resolution_m)


def dominant_angle(classes_map: npt.NDArray[np.uint8], *, min_angle_rad: float, min_length_cells: int = 10,
                   bin_rad: float = math.radians(0.5)) -> float:
    """The map's dominant wall direction modulo a right angle, radians in [-pi/4, pi/4) (x = column, y = row).

    Hough line segments (OpenCV probabilistic Hough, half-degree steps) on the wall cells that touch a
    non-wall cell (solid blocks vote with their outline only) vote with their length into a circular
    histogram of directions modulo 90 degrees; the peak, smoothed over +-1.5 degrees, is refined to the
    length-weighted circular mean of the segments within +-2 degrees of it. Returns 0 when that is within
    ``min_angle_rad`` of the grid's axes or no segment is found.
    """
    walls = (classes_map == CellClass.WALL).astype(np.uint8)
    edges = walls & cv2.dilate(1 - walls, np.ones((3, 3), np.uint8))
    segs = cv2.HoughLinesP(edges * 255, 1, math.pi / 360, threshold=max(min_length_cells // 2, 3),
                           minLineLength=min_length_cells, maxLineGap=3)
    if segs is None:
        return 0.0
    x0, y0, x1, y1 = segs.reshape(-1, 4).astype(np.float64).T
    length = np.hypot(x1 - x0, y1 - y0)
    quarter = math.pi / 2
    angle = (np.arctan2(y1 - y0, x1 - x0) + math.pi / 4) % quarter - math.pi / 4
    n = round(quarter / bin_rad)
    hist = np.bincount(((angle + math.pi / 4) / quarter * n).astype(np.int64) % n, weights=length, minlength=n)
    half = max(1, round(math.radians(1.5) / bin_rad))
    smooth = np.convolve(np.r_[hist[-half:], hist, hist[:half]], np.ones(2 * half + 1), "valid")
    peak = (int(np.argmax(smooth)) + 0.5) / n * quarter - math.pi / 4
    near = np.abs((angle - peak + math.pi / 4) % quarter - math.pi / 4) <= math.radians(2.0)
    mean = float(np.angle(np.sum(length[near] * np.exp(4j * angle[near])))) / 4  # circular mean modulo 90 degrees
    return 0.0 if abs(mean) < min_angle_rad else mean


def to_work(frame: Frame, grid: npt.NDArray[np.uint8], *, fill: int) -> npt.NDArray[np.uint8]:
    """A map grid (uint8) resampled into the working frame (nearest cell; ``fill`` outside the map)."""
    if not frame.turned:
        return grid
    h, w = frame.shape
    return np.asarray(cv2.warpAffine(grid, frame.matrix, (w, h), flags=cv2.INTER_NEAREST,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=fill), np.uint8)


def to_map(frame: Frame, grid: npt.NDArray[_Cell], *, fill: float) -> npt.NDArray[_Cell]:
    """A working-frame grid (uint8 or float32) resampled back onto the map's cells (nearest cell)."""
    if not frame.turned:
        return grid
    h, w = frame.map_shape
    return np.asarray(cv2.warpAffine(grid, frame.matrix, (w, h), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=fill), grid.dtype)


def points_to_map(frame: Frame, rc: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(N, 2) working-frame cell-corner coordinates (row, column) -> map cell-corner coordinates (row, column)."""
    if not frame.turned:
        return rc
    inverse = cv2.invertAffineTransform(frame.matrix)
    xy = np.stack([rc[:, 1] - 0.5, rc[:, 0] - 0.5])
    back = inverse[:, :2] @ xy + inverse[:, 2:]
    out: npt.NDArray[np.float64] = np.stack([back[1] + 0.5, back[0] + 0.5], axis=1)
    return out


def points_to_work(frame: Frame, rc: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(N, 2) map cell-corner coordinates (row, column) -> working-frame cell-corner coordinates."""
    if not frame.turned:
        return rc
    xy = np.stack([rc[:, 1] - 0.5, rc[:, 0] - 0.5])
    work = frame.matrix[:, :2] @ xy + frame.matrix[:, 2:]
    out: npt.NDArray[np.float64] = np.stack([work[1] + 0.5, work[0] + 0.5], axis=1)
    return out


def _point_to_work(frame: Frame, row: float, col: float) -> tuple[float, float]:
    x, y = frame.matrix[:, :2] @ np.array([col - 0.5, row - 0.5]) + frame.matrix[:, 2]
    return float(y + 0.5), float(x + 0.5)


def carry(world: World, old: Frame, new: Frame) -> World:
    """``world`` (cells of ``old``) moved into ``new``, a frame of the same angle over a grown or shifted map.

    Between two frames of one angle the cells only shift: the shift of the working frame's corner (old
    working cells -> old map cells -> metres -> new map cells -> new working cells), rounded, moves every
    unit and door alike, so shared walls stay shared.
    """
    (row, col), = points_to_map(old, np.zeros((1, 2)))
    x = old.origin_xy_m[0] + col * old.resolution_m
    y = old.origin_xy_m[1] + row * old.resolution_m
    nr, nc = _point_to_work(new, (y - new.origin_xy_m[1]) / new.resolution_m,
                            (x - new.origin_xy_m[0]) / new.resolution_m)
    dr, dc = round(nr), round(nc)

    def shift(r: Rect) -> Rect:
        return Rect(r.r0 + dr, r.r1 + dr, r.c0 + dc, r.c1 + dc)

    return World({u: shift(r) for u, r in world.units.items()}, {shift(d) for d in world.doors}, world.next_id)
