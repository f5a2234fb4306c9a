"""Smoothing back end: sensor poses and landmarks estimated together from localisation, odometry and bearings.

The EKF front end (:mod:`~services.pillar_mapping.mapper`) takes each frame's pose from the
localisation as given, so a slowly varying localisation error moves every upright mapped during
it. Here the poses of a window of frames are estimated jointly with the landmarks they saw, as
nonlinear least squares over a GTSAM factor graph:

- a ``PriorFactorPose2`` per frame: the localisation's pose with its covariance;
- a ``BetweenFactorPose2`` between consecutive frames of one robot: the odometry's relative
  motion, with noise growing with the distance driven and the angle turned (relative motion is
  far more precise than absolute localisation, so the trajectory keeps its shape and its offset
  is the average of many localisation errors, not one);
- a ``BearingFactor2D`` per associated bearing (Huber-robust), and a weak prior on each
  landmark at its front-end estimate, so a landmark seen from few frames stays determined.

An odometry step that disagrees with the localisation's by more than any drift could explain
(a reset of the odometry frame, e.g. a new run) is left out rather than trusted.
"""

from __future__ import annotations

from typing import NamedTuple

import gtsam
import numpy as np
import numpy.typing as npt

from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.triangulation import wrap

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_LANDMARK_PRIOR_M = 1.0
_POSE_FLOOR = np.array([1e-3, 1e-3, 1e-4])
_HUBER_K = 1.345


class FrameLog(NamedTuple):
    """Frames of a window: localisation ``poses`` (F, 3) and ``covs`` (F, 3, 3), ``odometry`` poses (F, 3)
    (NaN where none), ``tracks`` (F,) one id per robot (odometry links only frames of one track)."""

    poses: FloatArray
    covs: FloatArray
    odometry: FloatArray
    tracks: IntArray


class BearingLog(NamedTuple):
    """Associated bearings: ``frame`` (K,) index into the frame log, ``landmark`` (K,), vehicle-frame
    ``bearing`` (K,) and its std ``sigma`` (K,), radians."""

    frame: IntArray
    landmark: IntArray
    bearing: FloatArray
    sigma: FloatArray


class OdometryNoise(NamedTuple):
    """Odometry noise per step: ``sigma_m + per_m * distance`` across and along, heading
    ``sigma_rad + rad_per_m * distance + per_rad * |turn|``. The defaults are wheel odometry with
    a 1 % scale error and a gyro bias of 0.002 rad/s at about 1 m/s, as the simulator drifts it."""

    sigma_m: float = 0.002
    per_m: float = 0.01
    sigma_rad: float = 0.0005
    rad_per_m: float = 0.002
    per_rad: float = 0.01


class SmoothedMap(NamedTuple):
    """Result: ``landmarks`` (M,) indices re-estimated, their ``means`` (M, 2) and ``covs`` (M, 2, 2),
    the frames' ``poses`` (F, 3), and ``odometry_steps`` used / ``odometry_rejected`` (left out)."""

    landmarks: IntArray
    means: FloatArray
    covs: FloatArray
    poses: FloatArray
    odometry_steps: int
    odometry_rejected: int


def _relative(a: FloatArray, b: FloatArray) -> FloatArray:
    """Poses ``b`` (n, 3) in the frames of ``a`` (n, 3)."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    d = b[:, :2] - a[:, :2]
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap(b[:, 2] - a[:, 2])])


def odometry_steps(frames: FrameLog, noise: OdometryNoise) -> tuple[IntArray, FloatArray, FloatArray, int]:
    """Consecutive frames of one track linked by odometry: (S,) first frame index, (S, 3) relative
    motion, (S, 3) its std, and how many steps were left out as inconsistent with localisation."""
    order = np.lexsort((np.arange(len(frames.tracks)), frames.tracks))
    i, j = order[:-1], order[1:]
    pair = (frames.tracks[i] == frames.tracks[j]) & np.all(np.isfinite(frames.odometry[i]), axis=1)
    pair &= np.all(np.isfinite(frames.odometry[j]), axis=1)
    i, j = i[pair], j[pair]
    step = _relative(frames.odometry[i], frames.odometry[j])
    distance = np.hypot(step[:, 0], step[:, 1])
    sigma_xy = noise.sigma_m + noise.per_m * distance
    sigma_yaw = noise.sigma_rad + noise.rad_per_m * distance + noise.per_rad * np.abs(step[:, 2])
    sigmas = np.column_stack([sigma_xy, sigma_xy, sigma_yaw])
    # A step the localisation contradicts beyond both their errors (8 sigma) is an odometry reset.
    located = _relative(frames.poses[i], frames.poses[j])
    loc_sd = np.sqrt(np.einsum("kii->ki", frames.covs[i]) + np.einsum("kii->ki", frames.covs[j])) + _POSE_FLOOR
    diff = np.column_stack([located[:, :2] - step[:, :2], wrap(located[:, 2] - step[:, 2])])
    ok = np.all(np.abs(diff) <= 8.0 * np.hypot(sigmas, loc_sd), axis=1)
    return i[ok], step[ok], sigmas[ok], int((~ok).sum())


def smooth_map(frames: FrameLog, bearings: BearingLog, initial: FloatArray, *,
               odometry: OdometryNoise | None = None, fixed: IntArray | None = None,
               fixed_covs: FloatArray | None = None, iterations: int = 30) -> SmoothedMap:
    """Jointly estimate the frames' poses and the landmarks they saw (see the module docstring).

    Parameters
    ----------
    frames : FrameLog
        The window's frames (sensor poses in the map frame, odometry sensor poses in a robot's
        odometry frame).
    bearings : BearingLog
        The bearings associated with landmarks in those frames.
    initial : ndarray of float64, shape (N, 2)
        Every landmark's current estimate; those with at least two bearings are re-estimated.
    fixed, fixed_covs : ndarray of int64, shape (P,), and of float64, shape (N, 2, 2)
        Landmarks that enter with their estimate and covariance (``fixed_covs[n]``) as a prior,
        constraining the poses, and are not returned (their older views left the window).

    Raises
    ------
    PillarMappingError
        On inconsistent input, or when the optimisation fails.
    """
    noise = odometry or OdometryNoise()
    count = len(frames.poses)
    if not (frames.covs.shape == (count, 3, 3) and frames.odometry.shape == (count, 3)
            and frames.tracks.shape == (count,)):
        raise PillarMappingError("frame log arrays must have one entry per frame")
    seen = np.bincount(bearings.landmark, minlength=len(initial)) if bearings.landmark.size else np.zeros(0, int)
    held = np.zeros(0, dtype=np.int64) if fixed is None else fixed
    held_covs = np.zeros((0, 2, 2)) if fixed_covs is None else fixed_covs
    if held.size and len(held_covs) != len(initial):
        raise PillarMappingError("fixed landmarks need one covariance per landmark")
    index = np.flatnonzero(seen >= 2).astype(np.int64)
    pinned = np.intersect1d(index, held)
    index = np.setdiff1d(index, held)
    use = np.isin(bearings.landmark, np.concatenate([index, pinned]))
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for k in range(count):
        pose = gtsam.Pose2(*frames.poses[k])
        cov = 0.5 * (frames.covs[k] + frames.covs[k].T) + np.diag(_POSE_FLOOR**2)
        graph.add(gtsam.PriorFactorPose2(gtsam.symbol("x", k), pose, gtsam.noiseModel.Gaussian.Covariance(cov)))
        values.insert(gtsam.symbol("x", k), pose)
    first, steps, sigmas, rejected = odometry_steps(frames, noise)
    order = np.lexsort((np.arange(count), frames.tracks))
    following = dict(zip(order[:-1].tolist(), order[1:].tolist(), strict=True))
    for k, step, sigma in zip(first.tolist(), steps, sigmas, strict=True):
        graph.add(gtsam.BetweenFactorPose2(gtsam.symbol("x", k), gtsam.symbol("x", following[k]),
                                           gtsam.Pose2(*step), gtsam.noiseModel.Diagonal.Sigmas(sigma)))
    weak = gtsam.noiseModel.Isotropic.Sigma(2, _LANDMARK_PRIOR_M)
    for n in index.tolist():
        point = np.asarray(initial[n], dtype=np.float64)
        graph.add(gtsam.PriorFactorPoint2(gtsam.symbol("l", n), point, weak))
        values.insert(gtsam.symbol("l", n), point)
    for n in pinned.tolist():
        point = np.asarray(initial[n], dtype=np.float64)
        cov = 0.5 * (held_covs[n] + held_covs[n].T) + np.eye(2) * 1e-8
        graph.add(gtsam.PriorFactorPoint2(gtsam.symbol("l", n), point, gtsam.noiseModel.Gaussian.Covariance(cov)))
        values.insert(gtsam.symbol("l", n), point)
    huber = gtsam.noiseModel.mEstimator.Huber.Create(_HUBER_K)
    for f, n, b, s in zip(bearings.frame[use].tolist(), bearings.landmark[use].tolist(),
                          bearings.bearing[use].tolist(), bearings.sigma[use].tolist(), strict=True):
        model = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Isotropic.Sigma(1, s))
        graph.add(gtsam.BearingFactor2D(gtsam.symbol("x", f), gtsam.symbol("l", n), gtsam.Rot2.fromAngle(b), model))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(iterations)
    try:
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        means = np.array([result.atPoint2(gtsam.symbol("l", n)) for n in index.tolist()]).reshape(-1, 2)
        keys = gtsam.KeyVector([gtsam.symbol("l", n) for n in index.tolist()])
        joint = np.zeros((0, 0))
        if index.size:
            joint = gtsam.Marginals(graph, result).jointMarginalCovariance(keys).fullMatrix()
        covs = np.array([joint[2 * k:2 * k + 2, 2 * k:2 * k + 2] for k in range(index.size)]).reshape(-1, 2, 2)
    except RuntimeError as err:
        raise PillarMappingError(f"smoothing failed: {err}") from err
    poses = np.array([[p.x(), p.y(), p.theta()] for p in (result.atPose2(gtsam.symbol("x", k))
                                                        for k in range(count))]).reshape(-1, 3)
    return SmoothedMap(index, means, covs, poses, len(first), rejected)
