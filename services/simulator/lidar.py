"""A 2-D lidar: exact ray casting against box footprints, then range noise and dropouts.

Every box a horizontal scan plane cuts contributes its four footprint edges. Each edge only
touches the beams between the bearings of its two ends, so the caster pairs every edge with just
those beams (a few for an upright, hundreds for a nearby wall) instead of testing every beam
against every edge; a k-d tree over edge midpoints culls edges beyond range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from services.simulator.errors import SimulatorError
from services.simulator.world import Boxes, FloatArray

_MAX_PIECE_M = 4.0
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class LidarModel:
    """A planar laser scanner: field of view, resolution, range, noise and mounting."""

    angle_min_rad: float = -0.75 * math.pi
    angle_increment_rad: float = math.radians(0.25)
    beams: int = 1081
    range_min_m: float = 0.05
    range_max_m: float = 30.0
    range_noise_m: float = 0.01
    """Standard deviation of Gaussian range noise, metres."""
    dropout: float = 0.002
    """Probability that a beam with a target returns nothing."""
    height_m: float = 0.2
    mount_xy_m: tuple[float, float] = (0.3, 0.0)
    rate_hz: float = 10.0

    def __post_init__(self) -> None:
        if not (self.beams > 0 and self.angle_increment_rad > 0 and 0 <= self.range_min_m < self.range_max_m
                and self.range_noise_m >= 0 and 0 <= self.dropout < 1 and self.rate_hz > 0):
            raise SimulatorError(f"unusable lidar model {self}")
        if self.beams * self.angle_increment_rad > _TWO_PI + 1e-9:
            raise SimulatorError(f"{self.beams} beams of {self.angle_increment_rad} rad cover more than a turn")

    @property
    def angle_max_rad(self) -> float:
        """Bearing of the last beam, radians."""
        return self.angle_min_rad + (self.beams - 1) * self.angle_increment_rad


class Segments:
    """Obstacle edges at one height, with a spatial index for range culling.

    Edges are sides of closed counter-clockwise outlines (their outside on the right), so a ray
    can first hit only an edge seen from outside; :func:`cast_rays` skips the others.

    Parameters
    ----------
    segments : (m, 2, 2) float64
        Edge end points, metres.
    labels : (m,) int
        A label per edge (e.g. the :class:`ObjectClass` of its box), returned with each hit.
    """

    def __init__(self, segments: FloatArray, labels: npt.NDArray[np.int64]) -> None:
        segments = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
        labels = np.asarray(labels).reshape(-1)
        if len(labels) != len(segments):
            raise SimulatorError(f"{len(segments)} segments but {len(labels)} labels")
        lengths = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
        pieces = np.maximum(1, np.ceil(lengths / _MAX_PIECE_M)).astype(np.int64)
        owner = np.repeat(np.arange(len(segments)), pieces)
        first = np.repeat(np.cumsum(pieces) - pieces, pieces)
        k = np.arange(len(owner)) - first
        t0, t1 = (k / pieces[owner])[:, None], ((k + 1) / pieces[owner])[:, None]
        a, b = segments[owner, 0], segments[owner, 1]
        self.starts = a + t0 * (b - a)
        self.ends = a + t1 * (b - a)
        self.labels = labels[owner]
        self._tree = cKDTree(0.5 * (self.starts + self.ends)) if len(owner) else None
        self._reach = 0.5 * float(np.hypot(*(self.ends - self.starts).T).max()) if len(owner) else 0.0

    @classmethod
    def from_boxes(cls, boxes: Boxes, *, height_m: float) -> Segments:
        """The footprint edges of the boxes a horizontal plane at ``height_m`` cuts, labelled by class."""
        cut = boxes.take((boxes.z_m[:, 0] <= height_m) & (boxes.z_m[:, 1] >= height_m))
        corners = cut.corners_xy()
        edges = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2).reshape(-1, 2, 2)
        return cls(edges, np.repeat(cut.kind.astype(np.int64), 4))

    def near(self, point: FloatArray, radius_m: float) -> npt.NDArray[np.intp]:
        """Indices of the edges that may come within ``radius_m`` of ``point``."""
        if self._tree is None:
            return np.zeros(0, np.intp)
        return np.asarray(self._tree.query_ball_point(point, radius_m + self._reach), dtype=np.intp)


def cast_rays(origin: FloatArray, first_bearing_rad: float, increment_rad: float, beams: int,
              segment_sets: list[tuple[Segments, npt.NDArray[np.intp] | None]], *, max_range_m: float
              ) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """Exact distance along each of ``beams`` evenly spaced rays to the nearest edge, and its label.

    Parameters
    ----------
    origin : (2,) float64
        Ray origin, metres.
    first_bearing_rad, increment_rad : float
        Map-frame bearing of the first ray and the step between rays, radians.
    beams : int
        Number of rays.
    segment_sets : list of (Segments, indices or None)
        Edge sets to cast against, each with the edge indices to use (None: all near enough).
    max_range_m : float
        Rays reaching nothing within this return +inf.

    Returns
    -------
    ranges : (beams,) float64
        Metres, +inf where nothing is hit.
    labels : (beams,) int64
        Label of the edge hit, -1 for no hit.
    """
    starts_l, ends_l, labels_l = [], [], []
    for segments, index in segment_sets:
        chosen = segments.near(origin, max_range_m) if index is None else index
        starts_l.append(segments.starts[chosen])
        ends_l.append(segments.ends[chosen])
        labels_l.append(segments.labels[chosen])
    p = np.concatenate(starts_l) - origin
    q = np.concatenate(ends_l) - origin
    edge_labels = np.concatenate(labels_l)
    # footprint edges run counter-clockwise: only those with the outside towards the origin can be hit first
    facing = p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0] < 0
    p, q, edge_labels = p[facing], q[facing], edge_labels[facing]
    ranges = np.full(beams, np.inf)
    hit_labels = np.full(beams, -1, np.int64)
    if len(p) == 0:
        return ranges, hit_labels
    ap, aq = np.arctan2(p[:, 1], p[:, 0]), np.arctan2(q[:, 1], q[:, 0])
    sweep = (aq - ap + math.pi) % _TWO_PI - math.pi
    low = np.where(sweep >= 0, ap, aq)
    offset = (low - first_bearing_rad) % _TWO_PI
    pair_edge_l, pair_beam_l = [], []
    for shift in (0.0, _TWO_PI):
        i0 = np.maximum(np.ceil((offset - shift) / increment_rad - 1e-9), 0).astype(np.int64)
        i1 = np.minimum(np.floor((offset - shift + np.abs(sweep)) / increment_rad + 1e-9), beams - 1).astype(np.int64)
        counts = np.maximum(i1 - i0 + 1, 0)
        edge = np.repeat(np.arange(len(p)), counts)
        pair_edge_l.append(edge)
        pair_beam_l.append(i0[edge] + np.arange(len(edge)) - np.repeat(np.cumsum(counts) - counts, counts))
    edge, beam = np.concatenate(pair_edge_l), np.concatenate(pair_beam_l)
    bearing = first_bearing_rad + beam * increment_rad
    dx, dy = np.cos(bearing), np.sin(bearing)
    px, py = p[edge, 0], p[edge, 1]
    ex, ey = q[edge, 0] - px, q[edge, 1] - py
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (px * ey - py * ex) / denom
        u = (px * dy - py * dx) / denom
    ok = (np.abs(denom) > 1e-12) & (t > 0) & (t <= max_range_m) & (u >= -1e-9) & (u <= 1 + 1e-9)
    edge, beam, t = edge[ok], beam[ok], t[ok]
    order = np.lexsort((t, beam))
    beam, t, edge = beam[order], t[order], edge[order]
    first = np.ones(len(beam), bool)
    first[1:] = beam[1:] != beam[:-1]
    ranges[beam[first]] = t[first]
    hit_labels[beam[first]] = edge_labels[edge[first]]
    return ranges, hit_labels


def add_noise(ranges: FloatArray, model: LidarModel, rng: np.random.Generator) -> FloatArray:
    """``ranges`` with Gaussian noise, random dropouts (+inf) and the model's range limits applied."""
    noisy = ranges + rng.normal(0.0, model.range_noise_m, ranges.shape) if model.range_noise_m > 0 else ranges.copy()
    noisy[rng.random(ranges.shape) < model.dropout] = np.inf
    noisy[(noisy > model.range_max_m) | ~np.isfinite(ranges)] = np.inf
    noisy[noisy < model.range_min_m] = model.range_min_m
    return noisy
