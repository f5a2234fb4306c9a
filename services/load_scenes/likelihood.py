"""Likelihood of a bay's scene against depth points (seed 003 eq. 4.4, as a ray model of an RGB-D view).

The seed scores a pose by reprojected keypoints. A depth camera gives more: each point is the end of a ray
from the camera, so a scene predicts where each ray stops, the first box face it enters (or the background
behind the bay). Per ray a beam-model mixture scores the measured range ``r`` against the predicted ``t``:
a Gaussian hit around ``t``, something unmodelled in front (uniform on [0, t]) and a uniform outlier. So a
point on a visible face is likely, a ray passing through a box (a ghost) unlikely, and a point inside the
bay's load volume that no box explains (a missed object) unlikely.

Cheap for the MCMC: the entry distance of every ray into every box is an (N, K) table computed once; a pose
move recomputes one column and a presence change only masks columns (:func:`scene_log_likelihood` takes the
per-ray minimum). Rays are subsampled to ``max_rays`` per bay.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, Field

from services.load_scenes.boxes import level_tops, to_bay_frame
from services.load_scenes.errors import SceneError
from services.load_scenes.model import Bay, DepthEvidence


class LikelihoodSettings(BaseModel):
    """The ray model's mixture and how many rays a bay's likelihood uses."""

    range_sigma_m: float = Field(0.03, gt=0.0, description="Depth noise plus the pose noise of a face.")
    hit_weight: float = Field(0.8, gt=0.0)
    short_weight: float = Field(0.1, ge=0.0)
    random_weight: float = Field(0.1, gt=0.0)
    max_range_m: float = Field(12.0, gt=0.0)
    ray_weight: float = Field(0.25, gt=0.0, le=1.0, description="Per-ray log-likelihood scale (rays are "
                              "correlated: neighbouring pixels see the same face).")
    max_rays: int = Field(800, ge=1)
    background_margin_m: float = Field(0.05, ge=0.0, description="Points this close to the bay's back, sides or "
                                       "floor are background, not load.")
    seed: int = 0


class Rays(NamedTuple):
    """N rays in the bay frame."""

    origin: npt.NDArray[np.float64]
    """(N, 3) camera centres."""
    direction: npt.NDArray[np.float64]
    """(N, 3) unit directions."""
    range_m: npt.NDArray[np.float64]
    """(N,) measured distance to the point."""
    point: npt.NDArray[np.float64]
    """(N, 3) the measured points."""
    background: npt.NDArray[np.bool_]
    """(N,) the point lies outside the bay's load volume (back, sides, floor, above): a ray that meets no box
    there is explained."""


def prepare_rays(bay: Bay, views: list[DepthEvidence], settings: LikelihoodSettings) -> Rays:
    """The rays of ``views`` that cross the bay, in its frame, at most ``settings.max_rays`` (seeded subsample).

    Points that are not finite are dropped. A view with a non-finite origin or points not shaped (N, 3)
    raises.

    Raises
    ------
    SceneError
        On a malformed view.
    """
    origins, points = [], []
    for view in views:
        pts = np.asarray(view.points, float)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise SceneError(f"depth points must be (N, 3), got {pts.shape}")
        if not all(math.isfinite(c) for c in view.origin):
            raise SceneError(f"depth view origin {view.origin} is not finite")
        pts = pts[np.isfinite(pts).all(axis=1)]
        points.append(pts)
        origins.append(np.broadcast_to(np.asarray(view.origin, float), pts.shape))
    if not points:
        return _rays(np.zeros((0, 3)), np.zeros((0, 3)), bay, settings)
    o_all, p_all = np.concatenate(origins), np.concatenate(points)
    rng = np.random.default_rng(settings.seed)
    if p_all.shape[0] > 4 * settings.max_rays:  # thin big clouds before the geometry (most rays cross the bay)
        pick = np.unique(rng.integers(0, p_all.shape[0], 4 * settings.max_rays))
        o_all, p_all = o_all[pick], p_all[pick]
    o = to_bay_frame(bay, o_all)
    p = to_bay_frame(bay, p_all)
    top = float(level_tops(bay)[-1])
    lo = np.array([-0.5 * bay.width_m, 0.0, 0.0])
    hi = np.array([0.5 * bay.width_m, bay.depth_m, top])
    d = p - o
    length = np.linalg.norm(d, axis=1)
    ok = length > 1e-6
    o, p, d, length = o[ok], p[ok], d[ok], length[ok]
    t = _slab_entry(o, d / length[:, None], 0.5 * (lo + hi), 0.5 * (hi - lo))
    crosses = t <= length + 0.1
    o, p = o[crosses], p[crosses]
    if o.shape[0] > settings.max_rays:
        pick = np.sort(rng.choice(o.shape[0], settings.max_rays, replace=False))
        o, p = o[pick], p[pick]
    return _rays(o, p, bay, settings)


def _rays(o: npt.NDArray[np.float64], p: npt.NDArray[np.float64], bay: Bay, s: LikelihoodSettings) -> Rays:
    d = p - o
    r = np.linalg.norm(d, axis=1)
    m = s.background_margin_m
    top = float(level_tops(bay)[-1])
    inside = ((np.abs(p[:, 0]) < 0.5 * bay.width_m - m) & (p[:, 1] >= 0.0) & (p[:, 1] < bay.depth_m - m)
              & (p[:, 2] > m) & (p[:, 2] < top))
    return Rays(origin=o, direction=d / np.maximum(r, 1e-9)[:, None], range_m=r, point=p, background=~inside)


def _slab_entry(
    o: npt.NDArray[np.float64], d: npt.NDArray[np.float64], centre: npt.NDArray[np.float64],
    half: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """Distance along unit rays (N, 3) to where they enter an axis-aligned box; inf when they miss it."""
    inv = 1.0 / np.where(np.abs(d) < 1e-12, 1e-12, d)
    t1 = (centre - half - o) * inv
    t2 = (centre + half - o) * inv
    near = np.minimum(t1, t2).max(axis=-1)
    far = np.maximum(t1, t2).min(axis=-1)
    hit = (near <= far) & (far > 0.0)
    return np.where(hit, np.maximum(near, 0.0), np.inf)


def entry_distances(
    rays: Rays, centre: npt.NDArray[np.float64], size: npt.NDArray[np.float64], yaw: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """Distance (N, K) along each ray to where it enters each upright box; inf when it misses.

    Parameters
    ----------
    rays
        N rays in the bay frame.
    centre, size : (K, 3)
        Boxes' centres and own sizes (x turned by ``yaw`` from the bay's u axis), metres.
    yaw : (K,)
        Radians.
    """
    c, s = np.cos(yaw), np.sin(yaw)  # (K,)
    rel = rays.origin[:, None, :] - centre[None, :, :]  # (N, K, 3)
    o = np.stack([c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1], rel[..., 2]], axis=-1)
    dr = rays.direction
    d = np.stack([c[None] * dr[:, None, 0] + s[None] * dr[:, None, 1],
                  -s[None] * dr[:, None, 0] + c[None] * dr[:, None, 1],
                  np.broadcast_to(dr[:, None, 2], o.shape[:2])], axis=-1)
    return _slab_entry(o, d, np.zeros(3), 0.5 * size[None])


def ray_log_likelihoods(
    rays: Rays, expected_m: npt.NDArray[np.float64], settings: LikelihoodSettings,
) -> npt.NDArray[np.float64]:
    """Per-ray log-likelihood of the measured ranges given the predicted ones, ``expected_m`` (..., N).

    A ray whose prediction is inf (it meets no box) is explained when its point is background and scores as
    an outlier when it lies in the bay's load volume.
    """
    s = settings
    r = rays.range_m
    norm = 1.0 / (s.range_sigma_m * math.sqrt(2.0 * math.pi))
    rand = s.random_weight / s.max_range_m
    finite = np.isfinite(expected_m)
    t = np.where(finite, expected_m, 0.0)
    hit = s.hit_weight * norm * np.exp(-0.5 * ((r - t) / s.range_sigma_m) ** 2)
    short = np.where(r < t, s.short_weight / np.maximum(t, 1e-3), 0.0)
    boxed = np.log(hit + short + rand)
    unboxed = np.where(rays.background, math.log(s.hit_weight * norm + rand), math.log(rand))
    result: npt.NDArray[np.float64] = np.where(finite, boxed, unboxed)
    return result


def scene_log_likelihood(
    rays: Rays, table: npt.NDArray[np.float64], present: npt.NDArray[np.bool_], settings: LikelihoodSettings,
) -> float:
    """Log-likelihood of the depth rays given which boxes are present: (N, K) entry table, (K,) mask."""
    if table.shape[0] == 0:
        return 0.0
    expected = np.where(present[None, :], table, np.inf).min(axis=1)
    return settings.ray_weight * float(ray_log_likelihoods(rays, expected, settings).sum())
