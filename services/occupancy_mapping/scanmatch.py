"""Correlative scan-to-map matching (Olson 2009): keeps odometry drift from smearing walls.

Each scan is scored against a likelihood field of the grid's walls (a Gaussian of the distance
to the nearest occupied cell) at every pose of a small window around the predicted pose, coarse
to fine. A better pose is taken only when it scores clearly better than the prediction, so a
map built from poses that are already right is left alone; the correction is kept as a drift
estimate (like a ``map -> odom`` transform) and applied to every later prediction.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.occupancy_mapping.errors import OccupancyMappingError
from services.occupancy_mapping.grid import OccupancyGrid
from services.occupancy_mapping.scan import ScanArrays
from shared.transforms import Pose2D

log = logging.getLogger(__name__)

OCCUPIED_LOGODDS = math.log(0.65 / 0.35)
"""Cells above this log-odds (65 %, map_saver's threshold) are walls to match against."""

_IDENTITY = Pose2D(0.0, 0.0, 0.0)


class MatchResult(NamedTuple):
    """Result of :func:`match_scan`: the best pose and the mean likelihood there and at the prior (in [0, 1])."""

    pose: Pose2D
    score: float
    prior_score: float


def compose_poses(a: Pose2D, b: Pose2D) -> Pose2D:
    """``a * b``: pose ``b`` given in frame ``a``, expressed in ``a``'s parent frame."""
    c, s = math.cos(a.yaw_rad), math.sin(a.yaw_rad)
    return Pose2D(a.x_m + c * b.x_m - s * b.y_m, a.y_m + s * b.x_m + c * b.y_m, a.yaw_rad + b.yaw_rad)


def invert_pose(a: Pose2D) -> Pose2D:
    """The inverse of the rigid transform ``a``."""
    c, s = math.cos(a.yaw_rad), math.sin(a.yaw_rad)
    return Pose2D(-(c * a.x_m + s * a.y_m), s * a.x_m - c * a.y_m, -a.yaw_rad)


def likelihood_field(occupied: npt.NDArray[np.bool_], *, sigma_cells: float) -> npt.NDArray[np.float32]:
    """How likely a beam ending in each cell hit a wall: ``exp(-d^2 / (2 sigma^2))``.

    Parameters
    ----------
    occupied : (rows, cols) bool
        Wall cells.
    sigma_cells : float
        Spread of the Gaussian, in cells.

    Returns
    -------
    (rows, cols) float32
        1 on walls, falling with the Euclidean distance ``d`` (cells) to the nearest wall; 0
        everywhere when there is no wall.
    """
    if occupied.ndim != 2:
        raise OccupancyMappingError(f"occupied must be 2-D, got shape {occupied.shape}")
    if not (math.isfinite(sigma_cells) and sigma_cells > 0):
        raise OccupancyMappingError(f"sigma_cells must be positive, got {sigma_cells}")
    if not occupied.any():
        return np.zeros(occupied.shape, np.float32)
    distance = cv2.distanceTransform((~occupied).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
    field = cv2.exp(distance * distance * np.float32(-0.5 / sigma_cells**2))
    return np.asarray(field, dtype=np.float32)


def _parabolic_peak(before: float, at: float, after: float) -> float:
    """Offset in (-0.5, 0.5) steps of the vertex of the parabola through three equally spaced scores."""
    curvature = before - 2.0 * at + after
    if curvature >= 0.0:
        return 0.0
    return float(np.clip(0.5 * (before - after) / curvature, -0.5, 0.5))


def border_cells(window_m: float, resolution_m: float) -> int:
    """Width of the zero border a likelihood field needs for a search of half-width ``window_m``, cells."""
    return 2 * max(1, math.ceil(window_m / resolution_m)) + 3


def _scores(
    flat_field: npt.NDArray[np.float32],
    width: int,
    points_m: npt.NDArray[np.float64],
    origin_m: npt.NDArray[np.float64],
    yaws_rad: npt.NDArray[np.float64],
    offsets_cr: npt.NDArray[np.int64],
    resolution_m: float,
    border: int,
    *,
    bilinear: bool,
) -> npt.NDArray[np.float64]:
    """Summed likelihood of ``points_m`` at every (yaw, cell offset), (len(yaws), len(offsets)).

    ``bilinear`` interpolates between cell centres (smooth in the pose, four times the work);
    otherwise each point takes the value of the cell it falls in.
    """
    c, s = np.cos(yaws_rad)[:, None], np.sin(yaws_rad)[:, None]
    half = 0.5 if bilinear else 0.0  # bilinear works on coordinates with cell centres at integers
    x = (c * points_m[None, :, 0] - s * points_m[None, :, 1] + origin_m[0]) / resolution_m - half
    y = (s * points_m[None, :, 0] + c * points_m[None, :, 1] + origin_m[1]) / resolution_m - half
    col, row = np.floor(x), np.floor(y)
    height = flat_field.size // width
    inside = (col >= border) & (row >= border) & (col < width - border - 1) & (row < height - border - 1)
    # points off the window go to the middle of the zero border's corner, where every offset scores 0
    corner = border // 2
    base = np.where(inside, row * width + col, corner * width + corner).astype(np.int64)
    index = base[:, None, :] + (offsets_cr[:, 1] * width + offsets_cr[:, 0])[None, :, None]
    if not bilinear:
        return np.asarray(flat_field[index].sum(axis=2, dtype=np.float64))
    fx, fy = (x - col)[:, None, :], (y - row)[:, None, :]
    low = flat_field[index] * (1.0 - fx) + flat_field[index + 1] * fx
    high = flat_field[index + width] * (1.0 - fx) + flat_field[index + width + 1] * fx
    return np.asarray((low * (1.0 - fy) + high * fy).sum(axis=2))


def match_scan(
    field: npt.NDArray[np.float32],
    *,
    field_origin_m: tuple[float, float],
    resolution_m: float,
    prior: Pose2D,
    points_m: npt.NDArray[np.float64],
    window_m: float,
    window_rad: float,
    motion_cost: float = 0.1,
) -> MatchResult:
    """Best sensor pose within ``window_m`` / ``window_rad`` of ``prior``, by correlative search.

    A coarse search (two-cell steps, yaw steps that move the far returns by about three cells)
    picks the best pose; a fine search around it at one-cell and half-step yaw resolution,
    interpolating the field bilinearly, with a parabolic fit per axis, refines it. All
    candidates of a level are scored at once: the points are rotated once per yaw, then cell
    offsets are added to flat indices. Every score is the mean likelihood of the points minus
    ``motion_cost * ((d / window_m)^2 + (dyaw / window_rad)^2)`` for a move ``d``, ``dyaw`` from
    the prior, so flat directions (a corridor's axis) keep the prior.

    Parameters
    ----------
    field : (rows, cols) float32
        Likelihood field (:func:`likelihood_field`) with a zero border :func:`border_cells` wide.
    field_origin_m : (float, float)
        World (x, y) of the lower-left corner of ``field[0, 0]``, metres, on the cell lattice.
    resolution_m : float
        Cell size, metres.
    prior : Pose2D
        Predicted sensor pose.
    points_m : (n, 2) float64
        Beam end points in the sensor frame, metres; ``n >= 1``.
    window_m, window_rad : float
        Half-widths of the search window in x and y (metres) and in yaw (radians).
    motion_cost : float
        Score (mean likelihood) a move to the edge of the window costs.

    Returns
    -------
    MatchResult
        Best pose, and the score there and at ``prior`` (bilinear, motion cost included).
    """
    if points_m.ndim != 2 or points_m.shape[1] != 2 or len(points_m) == 0:
        raise OccupancyMappingError(f"points_m must be (n, 2) with n >= 1, got shape {points_m.shape}")
    if not (window_m > 0 and window_rad > 0 and resolution_m > 0 and motion_cost >= 0):
        raise OccupancyMappingError("window_m, window_rad and resolution_m must be positive and motion_cost >= 0")
    width = field.shape[1]
    flat = field.ravel()
    reach = max(1, math.ceil(window_m / resolution_m))
    border = border_cells(window_m, resolution_m)
    origin = np.array([prior.x_m - field_origin_m[0], prior.y_m - field_origin_m[1]])
    squared = np.einsum("ij,ij->i", points_m, points_m)
    k = (9 * len(squared)) // 10
    far_m = math.sqrt(float(np.partition(squared, k)[k]))  # 90th percentile of the ranges
    yaw_step = min(math.radians(1.0), max(math.radians(0.1), 3.0 * resolution_m / max(far_m, 1e-6)))
    n_yaw = math.ceil(window_rad / yaw_step)
    yaws = prior.yaw_rad + yaw_step * np.arange(-n_yaw, n_yaw + 1, dtype=np.float64)
    steps = np.arange(-reach, reach + 1, 2)
    coarse = np.stack(np.meshgrid(steps, steps), axis=-1).reshape(-1, 2)

    n = len(points_m)
    per_m2 = (resolution_m / window_m) ** 2

    def score(
        yaw_values: npt.NDArray[np.float64],
        offsets: npt.NDArray[np.int64],
        *,
        bilinear: bool = False,
        sub_cell: tuple[float, float] = (0.0, 0.0),
    ) -> npt.NDArray[np.float64]:
        at = origin + np.asarray(sub_cell) * resolution_m
        mean = _scores(flat, width, points_m, at, yaw_values, offsets, resolution_m, border, bilinear=bilinear) / n
        moved = ((offsets[:, 0] + sub_cell[0]) ** 2 + (offsets[:, 1] + sub_cell[1]) ** 2) * per_m2
        turned = ((yaw_values - prior.yaw_rad) / window_rad) ** 2
        return mean - motion_cost * (turned[:, None] + moved[None, :])

    zero = np.zeros((1, 2), np.int64)
    prior_score = float(score(np.array([prior.yaw_rad]), zero, bilinear=True)[0, 0])
    coarse_scores = score(yaws, coarse)
    i_yaw, i_off = np.unravel_index(int(np.argmax(coarse_scores)), coarse_scores.shape)
    best_yaw, best_off = float(yaws[i_yaw]), coarse[i_off]
    unit = np.arange(-1, 2)
    fine_offsets = best_off[None, :] + np.stack(np.meshgrid(unit, unit), axis=-1).reshape(-1, 2)
    fine_offsets = np.clip(fine_offsets, -reach - 1, reach + 1)
    fine_yaws = best_yaw + 0.5 * yaw_step * unit.astype(np.float64)
    fine = score(fine_yaws, fine_offsets, bilinear=True).reshape(3, 3, 3)  # (yaw, dy, dx)
    j_yaw, j_y, j_x = np.unravel_index(int(np.argmax(fine)), fine.shape)
    best = float(fine[j_yaw, j_y, j_x])
    off = fine_offsets[j_y * 3 + j_x]
    best_pose = Pose2D(
        prior.x_m + float(off[0]) * resolution_m, prior.y_m + float(off[1]) * resolution_m, float(fine_yaws[j_yaw])
    )
    dx = _parabolic_peak(*(float(v) for v in fine[j_yaw, j_y, :])) if 0 < j_x < 2 else 0.0
    dy = _parabolic_peak(*(float(v) for v in fine[j_yaw, :, j_x])) if 0 < j_y < 2 else 0.0
    dyaw = _parabolic_peak(*(float(v) for v in fine[:, j_y, j_x])) if 0 < j_yaw < 2 else 0.0
    if dx or dy or dyaw:
        yaw = float(fine_yaws[j_yaw]) + dyaw * 0.5 * yaw_step
        refined = float(score(np.array([yaw]), off[None, :], bilinear=True, sub_cell=(dx, dy))[0, 0])
        if refined > best:
            best = refined
            best_pose = Pose2D(best_pose.x_m + dx * resolution_m, best_pose.y_m + dy * resolution_m, yaw)
    pose = best_pose._replace(yaw_rad=math.remainder(best_pose.yaw_rad, math.tau))
    return MatchResult(pose, best, prior_score)


@dataclass
class _Window:
    field: npt.NDArray[np.float32]
    col0: int  # world cell index of field column 0
    row0: int
    walls: int
    age_scans: int


@dataclass
class _Track:
    drift: Pose2D = _IDENTITY
    scans: int = 0
    window: _Window | None = None


class ScanMatcher:
    """A :data:`~services.occupancy_mapping.mapper.ScanCorrector` by correlative scan matching.

    Call it with the grid, the odometry-predicted sensor pose and the scan; it returns the pose
    to integrate the scan at. Each sensor frame (one per robot) keeps its own drift estimate
    (``map <- odom``, :meth:`drift`), which is applied to every prediction and updated when a
    match is accepted. A match is accepted only when the first ``warmup_scans`` scans of that
    frame are in, the scan has ``min_returns`` usable returns, the local map has
    ``min_wall_cells`` wall cells, the map explains the scan well at the best pose (score at
    least ``min_score``) and the best pose scores at least ``min_gain`` above the prediction
    (scores are mean likelihoods in [0, 1] less the motion cost, see :func:`match_scan`).
    Otherwise the prediction (with the drift estimate) is returned unchanged.

    The likelihood field is computed on a window of the grid around the sensor (the scan's
    extent plus ``margin_m``) and reused for ``refresh_scans`` scans or until the sensor leaves it.

    Parameters
    ----------
    window_m : float
        Half-width of the position search, metres.
    window_rad : float
        Half-width of the heading search, radians.
    max_range_m : float
        Returns at or beyond this are not matched.
    sigma_cells : float
        Spread of the likelihood around walls, cells.
    motion_cost : float
        Score a move to the edge of the search window costs, so flat directions keep the prediction.
    min_gain, min_score : float
        Acceptance thresholds, see above.
    warmup_scans, min_returns, min_wall_cells : int
        Structure needed before matching, see above.
    max_points : int
        Returns used per scan, evenly spread over the scan.
    margin_m : float
        Extra extent of the likelihood window around the scan, metres.
    refresh_scans : int
        Scans a likelihood window is reused for.
    """

    def __init__(
        self,
        *,
        window_m: float = 0.3,
        window_rad: float = math.radians(5.0),
        max_range_m: float = 30.0,
        sigma_cells: float = 1.5,
        motion_cost: float = 0.1,
        min_gain: float = 0.005,
        min_score: float = 0.6,
        warmup_scans: int = 10,
        min_returns: int = 30,
        min_wall_cells: int = 100,
        max_points: int = 150,
        margin_m: float = 2.0,
        refresh_scans: int = 10,
    ) -> None:
        if not (math.isfinite(window_m) and window_m > 0 and math.isfinite(window_rad) and 0 < window_rad < math.pi):
            raise OccupancyMappingError(f"need window_m > 0 and 0 < window_rad < pi, got {window_m}, {window_rad}")
        if not (max_range_m > 0 and sigma_cells > 0 and min(motion_cost, min_gain, margin_m) >= 0 and min_score < 1):
            raise OccupancyMappingError(
                "max_range_m and sigma_cells must be positive, motion_cost, min_gain and margin_m >= 0, min_score < 1"
            )
        if min(warmup_scans, min_wall_cells) < 0 or min(min_returns, max_points, refresh_scans) < 1:
            raise OccupancyMappingError(
                "scan and cell counts must be non-negative (min_returns, max_points, refresh_scans at least 1)"
            )
        self.window_m, self.window_rad = float(window_m), float(window_rad)
        self.max_range_m, self.sigma_cells = float(max_range_m), float(sigma_cells)
        self.motion_cost, self.min_gain, self.min_score = float(motion_cost), float(min_gain), float(min_score)
        self.warmup_scans, self.min_returns, self.min_wall_cells = warmup_scans, min_returns, min_wall_cells
        self.max_points, self.margin_m, self.refresh_scans = max_points, float(margin_m), refresh_scans
        self._tracks: dict[str, _Track] = {}
        self.counts: Counter[str] = Counter()

    def drift(self, frame_id: str) -> Pose2D:
        """Current drift estimate of a sensor frame: the transform taking its predictions to the map."""
        track = self._tracks.get(frame_id)
        return track.drift if track else _IDENTITY

    def __call__(self, grid: OccupancyGrid, predicted: Pose2D, scan: ScanArrays) -> Pose2D:
        """Pose to integrate ``scan`` at: ``predicted`` corrected by the drift estimate and, if accepted, a match."""
        track = self._tracks.setdefault(scan.frame_id, _Track())
        prior = compose_poses(track.drift, predicted)
        track.scans += 1
        if track.scans <= self.warmup_scans or not all(math.isfinite(v) for v in predicted):
            return prior
        points = self._points(scan)
        if len(points) < self.min_returns:
            self.counts["match_few_returns"] += 1
            return prior
        window = self._window(track, grid, prior, points)
        if window.walls < self.min_wall_cells:
            self.counts["match_few_walls"] += 1
            return prior
        res = grid.resolution_m
        result = match_scan(
            window.field,
            field_origin_m=(window.col0 * res, window.row0 * res),
            resolution_m=res,
            prior=prior,
            points_m=points,
            window_m=self.window_m,
            window_rad=self.window_rad,
            motion_cost=self.motion_cost,
        )
        if result.score < self.min_score or result.score - result.prior_score < self.min_gain:
            self.counts["match_kept_prior"] += 1
            return prior
        self.counts["match_corrected"] += 1
        drift = compose_poses(result.pose, invert_pose(predicted))
        track.drift = drift._replace(yaw_rad=math.remainder(drift.yaw_rad, math.tau))
        log.debug(
            "scan at %d ns moved by (%.3f, %.3f) m, %.4f rad; score %.3f -> %.3f",
            scan.stamp_ns,
            result.pose.x_m - prior.x_m,
            result.pose.y_m - prior.y_m,
            math.remainder(result.pose.yaw_rad - prior.yaw_rad, math.tau),
            result.prior_score,
            result.score,
        )
        return result.pose

    def _points(self, scan: ScanArrays) -> npt.NDArray[np.float64]:
        """Usable return end points in the sensor frame, (n, 2) metres, at most ``max_points`` spread over the scan."""
        r, a = scan.ranges, scan.angles
        with np.errstate(invalid="ignore"):
            ok = (
                np.isfinite(r)
                & np.isfinite(a)
                & (r >= scan.range_min_m)
                & (r < min(scan.range_max_m, self.max_range_m))
            )
        r, a = r[ok], a[ok]
        stride = math.ceil(len(r) / self.max_points) if len(r) else 1
        r, a = r[::stride], a[::stride]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)

    def _window(self, track: _Track, grid: OccupancyGrid, prior: Pose2D, points: npt.NDArray[np.float64]) -> _Window:
        """The cached likelihood window of ``track``, recomputed when stale or when the sensor left it."""
        res = grid.resolution_m
        cell = np.array([prior.x_m, prior.y_m]) / res
        window = track.window
        if window is not None:
            window.age_scans += 1
            rows, cols = window.field.shape
            keep = self.margin_m / (2 * res)
            if (
                window.age_scans < self.refresh_scans
                and window.col0 + keep <= cell[0] < window.col0 + cols - keep
                and window.row0 + keep <= cell[1] < window.row0 + rows - keep
            ):
                return window
        c, s = math.cos(prior.yaw_rad), math.sin(prior.yaw_rad)
        ends = np.stack([c * points[:, 0] - s * points[:, 1], s * points[:, 0] + c * points[:, 1]], axis=1) / res
        pad = math.ceil((self.window_m + self.margin_m) / res) + 2
        lo = np.floor(np.minimum(ends.min(axis=0), 0.0) + cell).astype(np.int64) - pad
        hi = np.ceil(np.maximum(ends.max(axis=0), 0.0) + cell).astype(np.int64) + pad
        occupied = _wall_cells(grid, int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1]))
        field = likelihood_field(occupied, sigma_cells=self.sigma_cells)
        border = border_cells(self.window_m, res)
        field[:border], field[-border:], field[:, :border], field[:, -border:] = 0.0, 0.0, 0.0, 0.0
        track.window = _Window(field, int(lo[0]), int(lo[1]), int(np.count_nonzero(occupied)), 0)
        self.counts["match_fields"] += 1
        return track.window


def _wall_cells(grid: OccupancyGrid, col0: int, row0: int, col1: int, row1: int) -> npt.NDArray[np.bool_]:
    """Wall mask of world cells ``[col0, col1) x [row0, row1)``, (row1 - row0, col1 - col0) bool; False off the grid.

    Reads the grid's log-odds in place: a copy of a whole site map per scan would cost more than the match.
    """
    res = grid.resolution_m
    g_col, g_row = round(grid.origin_x_m / res), round(grid.origin_y_m / res)
    rows, cols = grid.shape
    out = np.zeros((row1 - row0, col1 - col0), dtype=bool)
    r0, r1 = max(row0, g_row), min(row1, g_row + rows)
    c0, c1 = max(col0, g_col), min(col1, g_col + cols)
    if r0 < r1 and c0 < c1:
        patch = grid._logodds[r0 - g_row : r1 - g_row, c0 - g_col : c1 - g_col]
        out[r0 - row0 : r1 - row0, c0 - col0 : c1 - col0] = patch > OCCUPIED_LOGODDS
    return out
