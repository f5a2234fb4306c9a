"""Bearing-only EKF mapping of uprights with the vehicle pose from localisation (paper A, section 3).

The state is the vehicle pose plus every landmark's position, as in Bailey's bearing-only
SLAM; but the vehicle is neither predicted nor updated here: its pose (and covariance, if given)
comes from the localisation topic each frame. The frames of a window are logged with their
odometry and the bearings associated in them, and :meth:`BearingOnlyMapper.smooth` re-estimates
poses and landmarks jointly (:mod:`~services.pillar_mapping.smoother`), so a slowly varying
localisation error is averaged out instead of copied into the map; the window's latest frames are
then mapped again from the smoothed poses with tight gates (re-association) and smoothed again.
With the vehicle known, landmarks stay uncorrelated, so the joint covariance is kept as its 2x2
landmark blocks, and the vehicle covariance enters each update as a considered (not estimated) uncertainty.
The measurement model (:func:`bearing_model`) gives the Jacobians with respect to both the vehicle and the
landmark, so estimating the vehicle as well (SLAM) adds the vehicle block and the
vehicle-landmark cross terms to the covariance and a prediction step, not a new model.

New landmarks are initialised in a delayed way: bearings that match no landmark wait in a
pool until rays from at least ``min_views`` frames, spanning at least ``min_parallax_rad``,
cross at one point; it is then triangulated and enters the filter with its covariance. A
pooled ray keeps its frame's pose uncertainty (heading variance added to the bearing's,
position variance turned into a bearing variance at the candidate's range), so rays from a
localisation a few centimetres and half a degree off still meet within their gates.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.association import associate
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.smoother import BearingLog, FrameLog, OdometryNoise, SmoothedMap, smooth_map
from services.pillar_mapping.triangulation import triangulate_bearings, wrap

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class LandmarkMap(NamedTuple):
    """Mapped uprights: ``means`` (N, 2) metres, ``covs`` (N, 2, 2) m^2, ``observations`` (N,) updates each."""

    means: FloatArray
    covs: FloatArray
    observations: IntArray


class FrameReport(NamedTuple):
    """What one frame did: bearings matched, ambiguous, pooled; landmarks initialised."""

    matched: int
    ambiguous: int
    pooled: int
    initialised: int


def bearing_model(pose: FloatArray, landmarks: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Bearings of landmarks from a sensor pose and their Jacobians.

    Parameters
    ----------
    pose : ndarray of float64, shape (3,)
        Sensor ``x, y`` (metres) and heading (radians) in the map.
    landmarks : ndarray of float64, shape (M, 2)
        Landmark positions, metres.

    Returns
    -------
    predicted : ndarray of float64, shape (M,)
        Bearings relative to the heading, radians in [-pi, pi).
    h_vehicle : ndarray of float64, shape (M, 3)
        d bearing / d (x, y, heading) of the sensor.
    h_landmark : ndarray of float64, shape (M, 2)
        d bearing / d (x, y) of the landmark.
    """
    delta = landmarks - pose[:2]
    q = np.maximum(np.sum(delta**2, axis=1), 1e-9)
    h_landmark = np.stack([-delta[:, 1] / q, delta[:, 0] / q], axis=1)
    h_vehicle = np.column_stack([-h_landmark, -np.ones(len(landmarks))])
    return wrap(np.arctan2(delta[:, 1], delta[:, 0]) - pose[2]), h_vehicle, h_landmark


@dataclass
class _RayPool:
    """Unmatched bearings waiting to start landmarks: ray ``origins`` (K, 2) and map ``angles`` (K,), their
    std ``sigmas`` (K,) with the heading's, the origin's position variance ``origin_vars`` (K,) m^2, ``frames``,
    and the vehicle-frame ``bearings`` (K,) with their own std ``bearing_sigmas`` (K,)."""

    origins: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    angles: FloatArray = field(default_factory=lambda: np.zeros(0))
    sigmas: FloatArray = field(default_factory=lambda: np.zeros(0))
    origin_vars: FloatArray = field(default_factory=lambda: np.zeros(0))
    frames: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    bearings: FloatArray = field(default_factory=lambda: np.zeros(0))
    bearing_sigmas: FloatArray = field(default_factory=lambda: np.zeros(0))

    def add(self, pose: FloatArray, bearings: FloatArray, bearing_sigmas: FloatArray, cov: FloatArray,
            frame: int) -> None:
        """Rays of ``bearings`` from ``pose`` with localisation covariance ``cov``."""
        origin, angles = pose[:2], wrap(pose[2] + bearings)
        sigmas, origin_var = np.sqrt(bearing_sigmas**2 + cov[2, 2]), float(np.linalg.eigvalsh(cov[:2, :2])[1])
        self.bearings = np.concatenate([self.bearings, bearings])
        self.bearing_sigmas = np.concatenate([self.bearing_sigmas, bearing_sigmas])
        self.origins = np.vstack([self.origins, np.tile(origin, (angles.size, 1))])
        self.angles = np.concatenate([self.angles, angles])
        self.sigmas = np.concatenate([self.sigmas, sigmas])
        self.origin_vars = np.concatenate([self.origin_vars, np.full(angles.size, origin_var)])
        self.frames = np.concatenate([self.frames, np.full(angles.size, frame, dtype=np.int64)])

    def keep(self, mask: npt.NDArray[np.bool_]) -> None:
        self.origins, self.angles = self.origins[mask], self.angles[mask]
        self.sigmas, self.origin_vars, self.frames = self.sigmas[mask], self.origin_vars[mask], self.frames[mask]
        self.bearings, self.bearing_sigmas = self.bearings[mask], self.bearing_sigmas[mask]

    def sigmas_at(self, rays: IntArray, distance_m: FloatArray) -> FloatArray:
        """Std (radians) of ``rays`` as seen at ``distance_m`` from their origins (shapes broadcast)."""
        return np.asarray(np.sqrt(self.sigmas[rays] ** 2 + self.origin_vars[rays] / np.maximum(distance_m, 0.05) ** 2))


@dataclass
class _WindowLog:
    """The latest frames (number, pose, covariance, odometry pose, track) and the bearings associated in them;
    ``partial`` lists the landmarks some of whose bearings have left the window."""

    frames: list[tuple[int, FloatArray, FloatArray, FloatArray, int]] = field(default_factory=list)
    frame: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    landmark: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    bearing: FloatArray = field(default_factory=lambda: np.zeros(0))
    sigma: FloatArray = field(default_factory=lambda: np.zeros(0))
    partial: set[int] = field(default_factory=set)
    raw: dict[int, tuple[FloatArray, FloatArray]] = field(default_factory=dict)

    def add_frame(self, number: int, pose: FloatArray, cov: FloatArray, odometry: FloatArray, track: int, *,
                  keep_after: int) -> None:
        self.frames = [f for f in self.frames if f[0] > keep_after]
        self.frames.append((number, pose.copy(), cov.copy(), odometry.copy(), track))
        self.raw = {f: b for f, b in self.raw.items() if f > keep_after}
        keep = self.frame > keep_after
        self.partial.update(self.landmark[~keep].tolist())
        self.frame, self.landmark = self.frame[keep], self.landmark[keep]
        self.bearing, self.sigma = self.bearing[keep], self.sigma[keep]

    def add_bearings(self, frame: IntArray, landmark: IntArray, bearing: FloatArray, sigma: FloatArray) -> None:
        self.frame = np.concatenate([self.frame, frame.astype(np.int64)])
        self.landmark = np.concatenate([self.landmark, landmark.astype(np.int64)])
        self.bearing = np.concatenate([self.bearing, bearing])
        self.sigma = np.concatenate([self.sigma, sigma])

    def keep_landmarks(self, keep: npt.NDArray[np.bool_]) -> None:
        """Forget the bearings of landmarks not in ``keep`` and renumber the others."""
        number = np.cumsum(keep) - 1
        mine = keep[self.landmark]
        self.keep_bearings(mine)
        self.landmark = number[self.landmark].astype(np.int64)
        self.partial = {int(number[n]) for n in self.partial if keep[n]}

    def keep_bearings(self, mask: npt.NDArray[np.bool_]) -> None:
        self.frame, self.landmark = self.frame[mask], self.landmark[mask]
        self.bearing, self.sigma = self.bearing[mask], self.sigma[mask]

    def logs(self) -> tuple[FrameLog, BearingLog]:
        numbers = np.array([f[0] for f in self.frames], dtype=np.int64)
        keep = np.isin(self.frame, numbers)
        frames = FrameLog(np.array([f[1] for f in self.frames]).reshape(-1, 3),
                          np.array([f[2] for f in self.frames]).reshape(-1, 3, 3),
                          np.array([f[3] for f in self.frames]).reshape(-1, 3),
                          np.array([f[4] for f in self.frames], dtype=np.int64))
        index = np.searchsorted(numbers, self.frame[keep])
        return frames, BearingLog(index.astype(np.int64), self.landmark[keep], self.bearing[keep], self.sigma[keep])


class BearingOnlyMapper:
    """EKF landmark map fed with bearings and externally known sensor poses.

    Parameters
    ----------
    max_range_m : float
        Landmarks farther than this from the sensor are not expected to be detected.
    gate_sq : float
        Chi-square gate on a bearing innovation (1 dof).
    sigma_floor_rad : float
        Least bearing standard deviation assumed, covering calibration and timing errors.
    min_views : int
        Frames whose rays must agree before a landmark is initialised.
    min_parallax_rad : float
        Least angle between those rays as seen from the landmark.
    window_frames : int
        How many frames unmatched bearings wait in the pool.
    min_support_ratio : float
        Least fraction of the pooled frames within range of a candidate that must have seen
        it: ghosts where rays of different uprights happen to cross get few.
    min_hit_ratio, min_observations : float, int
        A landmark is reliable while it was matched in at least ``min_hit_ratio`` of the frames
        that had it in range and in at least ``min_observations`` frames;
    min_pass_ratio : float
        and for good once one whole pass by it (a run of frames that had it in range, broken by
        ``window_frames`` without) matched it in at least this fraction of the pass's frames (and
        in ``min_observations``). An upright seen well on one pass then stays reliable when later
        passes have it in range but hidden (behind a rack, from the next aisle), where its overall
        ratio falls; a ghost where rays of different uprights crossed is matched in few frames of
        its pass and is not kept.
    smooth_window_frames : int
        How many of the latest frames (poses, odometry, associated bearings) :meth:`smooth`
        re-estimates.
    odometry_noise : OdometryNoise, optional
        Noise of the odometry steps between frames of one robot when smoothing.
    reassociate : bool
        After smoothing, map the latest frames again from the smoothed poses and smooth again
        (see :meth:`smooth`).
    replay_cov_scale : float
        The localisation covariance is scaled by this for the smoothed poses of that replay (the
        default, 1/16, takes their error as a quarter of the localisation's): tight gates.
    replay_frames : int
        How many frames before the last replay are replayed again with the frames since.
    """

    _CELL_M = 0.25

    def __init__(
        self,
        *,
        max_range_m: float = 8.0,
        gate_sq: float = 9.0,
        sigma_floor_rad: float = float(np.deg2rad(0.15)),
        min_views: int = 4,
        min_parallax_rad: float = float(np.deg2rad(10.0)),
        window_frames: int = 40,
        min_support_ratio: float = 0.6,
        min_hit_ratio: float = 0.3,
        min_observations: int = 6,
        min_pass_ratio: float = 0.4,
        smooth_window_frames: int = 1200,
        odometry_noise: OdometryNoise | None = None,
        reassociate: bool = True,
        replay_cov_scale: float = 0.0625,
        replay_frames: int = 120,
    ) -> None:
        if max_range_m <= 0 or gate_sq <= 0 or sigma_floor_rad <= 0:
            raise PillarMappingError("max_range_m, gate_sq and sigma_floor_rad must be positive")
        if min_views < 2 or window_frames < min_views:
            raise PillarMappingError(
                f"need min_views >= 2 and window_frames >= min_views, got {min_views}, {window_frames}"
            )
        self.max_range_m = max_range_m
        self.gate_sq = gate_sq
        self.sigma_floor_rad = sigma_floor_rad
        self.min_views = min_views
        self.min_parallax_rad = min_parallax_rad
        self.window_frames = window_frames
        self.min_support_ratio = min_support_ratio
        self.min_hit_ratio = min_hit_ratio
        self.min_observations = min_observations
        self.min_pass_ratio = min_pass_ratio
        self.smooth_window_frames = smooth_window_frames
        self.odometry_noise = odometry_noise or OdometryNoise()
        self.reassociate = reassociate
        self.replay_cov_scale = replay_cov_scale
        self.replay_frames = replay_frames
        self._log = _WindowLog()
        self._frame_origins: dict[int, FloatArray] = {}
        self._expected = np.zeros(0, dtype=np.int64)
        self._run_hits = np.zeros(0, dtype=np.int64)
        self._run_expected = np.zeros(0, dtype=np.int64)
        self._last_in_range = np.zeros(0, dtype=np.int64)
        self._confirmed = np.zeros(0, dtype=bool)
        self._means = np.zeros((0, 2))
        self._covs = np.zeros((0, 2, 2))
        self._counts = np.zeros(0, dtype=np.int64)
        self._pool = _RayPool()
        self._frame = 0
        self._replayed = 0
        self.vehicle_pose = np.zeros(3)
        self.vehicle_cov = np.zeros((3, 3))

    @property
    def landmarks(self) -> LandmarkMap:
        """The current map (copies)."""
        return LandmarkMap(self._means.copy(), self._covs.copy(), self._counts.copy())

    def seed(self, landmarks: LandmarkMap) -> None:
        """Start from known landmarks (e.g. from the map store after a restart).

        Each with at least ``min_observations`` counts as confirmed, so it stays reliable.
        """
        means = np.asarray(landmarks.means, dtype=np.float64).reshape(-1, 2)
        covs = np.asarray(landmarks.covs, dtype=np.float64).reshape(-1, 2, 2)
        counts = np.asarray(landmarks.observations, dtype=np.int64).ravel()
        if not (len(means) == len(covs) == len(counts)) or not np.all(np.isfinite(means)) or np.any(counts < 0):
            raise PillarMappingError("seed landmarks need finite means, one covariance and a count >= 0 each")
        if len(means) and np.any(np.linalg.eigvalsh(covs)[:, 0] <= 0):
            raise PillarMappingError("seed landmark covariances must be positive definite")
        self._log.partial.update(range(len(self._means), len(self._means) + len(means)))  # views before the window
        self._append(means, covs, counts, counts, counts >= self.min_observations)

    def _append(self, means: FloatArray, covs: FloatArray, counts: IntArray, expected: IntArray,
                confirmed: npt.NDArray[np.bool_]) -> None:
        """New landmarks, matched in ``counts`` of the ``expected`` frames of their first pass so far."""
        self._means = np.vstack([self._means, means])
        self._covs = np.concatenate([self._covs, covs])
        self._counts = np.concatenate([self._counts, counts])
        self._run_hits = np.concatenate([self._run_hits, counts])
        self._run_expected = np.concatenate([self._run_expected, expected])
        self._expected = np.concatenate([self._expected, expected])
        self._last_in_range = np.concatenate([self._last_in_range, np.full(len(means), self._frame, dtype=np.int64)])
        self._confirmed = np.concatenate([self._confirmed, confirmed])

    def reliable_landmarks(self) -> LandmarkMap:
        """The landmarks matched often enough overall, or confirmed by a whole pass (see ``min_pass_ratio``)."""
        ratio_ok = self._counts >= self.min_hit_ratio * self._expected
        keep = self._confirmed | ((self._counts >= self.min_observations) & ratio_ok)
        return LandmarkMap(self._means[keep].copy(), self._covs[keep].copy(), self._counts[keep].copy())

    def smooth(self) -> SmoothedMap | None:
        """Re-estimate the landmarks seen in the window jointly with the window's poses
        (:func:`~services.pillar_mapping.smoother.smooth_map`); None when there is nothing to smooth.

        A landmark some of whose bearings have left the window enters with its estimate and
        covariance as a prior and is left unchanged (its older views are no longer in the graph).
        With ``reassociate`` the latest frames are then mapped again from the smoothed poses, with
        tight gates (:meth:`_replay`: ghosts the raw localisation made go, merged uprights split,
        missed ones are initialised), and the window is smoothed again with those associations.

        Raises
        ------
        PillarMappingError
            When the optimisation fails (the map keeps its front-end estimates).
        """
        frames, bearings = self._log.logs()
        if len(frames.poses) == 0 or bearings.frame.size == 0:
            return None
        result = self._smooth_logged(frames, bearings)
        if self.reassociate:
            self._replay(result.poses, frames.covs)
            frames, bearings = self._log.logs()
            if bearings.frame.size:
                result = self._smooth_logged(frames, bearings)
        return result

    def _smooth_logged(self, frames: FrameLog, bearings: BearingLog) -> SmoothedMap:
        result = smooth_map(frames, bearings, self._means, odometry=self.odometry_noise,
                            fixed=np.array(sorted(self._log.partial), dtype=np.int64), fixed_covs=self._covs)
        self._means[result.landmarks] = result.means
        self._covs[result.landmarks] = result.covs
        return result

    def _replay(self, poses: FloatArray, covs: FloatArray) -> None:
        """Map the window's latest frames again from the smoothed ``poses`` (localisation ``covs`` scaled
        by ``replay_cov_scale``): the frames since the last replay and the ``replay_frames`` before them
        (their poses moved most since they were last replayed). The landmarks all of whose bearings lie
        in those frames are forgotten and found again with the tight gates good poses allow, so a ghost
        the raw poses made is not made again, two uprights merged into one landmark come back as two,
        and an upright missed is initialised. The others (seen before, or seeded) keep their estimates
        and statistics; they take part in association only."""
        numbers = np.array([f[0] for f in self._log.frames], dtype=np.int64)
        span = numbers > self._replayed - self.replay_frames
        start = int(numbers[span][0])
        keep = np.ones(len(self._means), dtype=bool)
        keep[self._log.landmark[self._log.frame >= start]] = False
        keep[self._log.landmark[self._log.frame < start]] = True
        keep[sorted(self._log.partial)] = True
        self._log.keep_landmarks(keep)
        self._log.keep_bearings(self._log.frame < start)  # the replay logs the others again
        state = ("_means", "_covs", "_counts", "_expected", "_run_hits", "_run_expected", "_last_in_range",
                 "_confirmed")
        saved = {name: getattr(self, name)[keep].copy() for name in state}
        for name, value in saved.items():
            setattr(self, name, value.copy())
        now, pose_now, cov_now = self._frame, self.vehicle_pose, self.vehicle_cov
        self._pool, self._frame_origins = _RayPool(), {}
        for number, pose, cov in zip(numbers[span].tolist(), poses[span], covs[span], strict=True):
            self._frame = number
            self._process(pose, self.replay_cov_scale * cov, *self._log.raw[number])
        kept = len(saved["_means"])
        for name, value in saved.items():
            getattr(self, name)[:kept] = value
        self._replayed = now
        self._frame, self.vehicle_pose, self.vehicle_cov = now, pose_now, cov_now

    def observe(
        self,
        sensor_pose: tuple[float, float, float],
        bearings_rad: npt.ArrayLike,
        sigmas_rad: npt.ArrayLike,
        *,
        pose_cov: FloatArray | None = None,
        odometry_pose: tuple[float, float, float] | None = None,
        track: int = 0,
    ) -> FrameReport:
        """Fold one frame's bearings into the map.

        Parameters
        ----------
        sensor_pose : (x, y, yaw)
            Sensor position in the map frame (metres) and the heading bearings are measured
            from (radians), from localisation.
        bearings_rad, sigmas_rad : array_like, shape (K,)
            Bearings relative to the sensor heading and their standard deviations, radians.
        pose_cov : ndarray, shape (3, 3), optional
            Localisation covariance of the sensor pose (m^2, rad^2); it widens the gates of
            association and initialisation and enters each update as considered uncertainty.
            Without it the pose is taken as exact.
        odometry_pose : (x, y, yaw), optional
            The sensor pose in the robot's odometry frame: consecutive frames of one ``track``
            (robot) are linked by its relative motion when the map is smoothed (:meth:`smooth`).
        """
        pose = np.asarray(sensor_pose, dtype=np.float64)
        odometry = np.full(3, np.nan) if odometry_pose is None else np.asarray(odometry_pose, dtype=np.float64)
        bearings = np.asarray(bearings_rad, dtype=np.float64).ravel()
        sigmas = np.asarray(sigmas_rad, dtype=np.float64).ravel()
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise PillarMappingError(f"sensor pose must be 3 finite numbers, got {pose.tolist()}")
        if bearings.shape != sigmas.shape or not (np.all(np.isfinite(bearings)) and np.all(sigmas > 0)):
            raise PillarMappingError("bearings and sigmas must be finite, of equal length, sigmas positive")
        cov = np.zeros((3, 3)) if pose_cov is None else np.asarray(pose_cov, dtype=np.float64)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)) or np.any(np.linalg.eigvalsh(0.5 * (cov + cov.T)) < 0):
            raise PillarMappingError("pose_cov must be a finite positive semi-definite 3x3 matrix")
        if odometry.shape != (3,) or not np.all(np.isfinite(odometry) | (odometry_pose is None)):
            raise PillarMappingError(f"odometry pose must be 3 finite numbers, got {odometry.tolist()}")
        sigmas = np.maximum(sigmas, self.sigma_floor_rad)
        self._frame += 1
        self._log.add_frame(self._frame, pose, cov, odometry, track, keep_after=self._frame - self.smooth_window_frames)
        self._log.raw[self._frame] = (bearings, sigmas)
        return self._process(pose, cov, bearings, sigmas)

    def _process(self, pose: FloatArray, cov: FloatArray, bearings: FloatArray, sigmas: FloatArray) -> FrameReport:
        """Associate, update, pool and initialise with frame ``self._frame``'s bearings from ``pose``."""
        self.vehicle_pose = pose
        self.vehicle_cov = cov
        self._frame_origins = {f: o for f, o in self._frame_origins.items() if f > self._frame - self.window_frames}
        self._frame_origins[self._frame] = pose[:2].copy()
        self._count_in_range(self._visible())
        matches, ambiguous, gated_any = self._associate(bearings, sigmas)
        self._update(bearings, sigmas, matches)
        fresh = (matches < 0) & ~gated_any
        self._pool.keep(self._pool.frames > self._frame - self.window_frames)
        self._pool.add(pose, bearings[fresh], sigmas[fresh], cov, self._frame)
        born = self._initialise()
        return FrameReport(int((matches >= 0).sum()), int(ambiguous.sum()), int(fresh.sum()), born)

    def _innovations(
        self, bearings: FloatArray, sigmas: FloatArray, index: IntArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Innovations (K, M), their variances (K, M) and landmark Jacobians (M, 2) for landmarks ``index``."""
        predicted, h_v, h_l = bearing_model(self.vehicle_pose, self._means[index])
        var_l = np.einsum("mi,mij,mj->m", h_l, self._covs[index], h_l)
        var_v = np.einsum("mi,ij,mj->m", h_v, self.vehicle_cov, h_v)
        innovation = wrap(bearings[:, None] - predicted[None, :])
        variance = sigmas[:, None] ** 2 + (var_l + var_v)[None, :]
        return innovation, variance, h_l

    def _visible(self) -> IntArray:
        d = np.hypot(*(self._means - self.vehicle_pose[:2]).T) if len(self._means) else np.zeros(0)
        return np.flatnonzero(d <= self.max_range_m)

    def _associate(
        self, bearings: FloatArray, sigmas: FloatArray
    ) -> tuple[IntArray, npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
        index = self._visible()
        innovation, variance, _ = self._innovations(bearings, sigmas, index)
        d2 = innovation**2 / variance
        local, ambiguous = associate(d2, gate_sq=self.gate_sq)
        matches = np.where(local >= 0, index[np.maximum(local, 0)] if index.size else -1, -1)
        gated: npt.NDArray[np.bool_] = np.asarray((d2 <= self.gate_sq).any(axis=1), dtype=bool)
        return matches.astype(np.int64), ambiguous, gated

    def _update(self, bearings: FloatArray, sigmas: FloatArray, matches: IntArray) -> None:
        obs = np.flatnonzero(matches >= 0)
        if obs.size == 0:
            return
        index = matches[obs]
        innovation, variance, h_l = self._innovations(bearings[obs], sigmas[obs], index)
        nu = innovation[np.arange(obs.size), np.arange(obs.size)]
        s = variance[np.arange(obs.size), np.arange(obs.size)]
        p = self._covs[index]
        ph = np.einsum("mij,mj->mi", p, h_l)
        gain = ph / s[:, None]
        self._means[index] += gain * nu[:, None]
        ikh = np.eye(2)[None] - gain[:, :, None] * h_l[:, None, :]
        r = (s - np.einsum("mi,mi->m", h_l, ph))[:, None, None]
        self._covs[index] = ikh @ p @ np.transpose(ikh, (0, 2, 1)) + r * gain[:, :, None] * gain[:, None, :]
        self._counts[index] += 1
        self._run_hits[index] += 1
        self._log.add_bearings(np.full(obs.size, self._frame), index, bearings[obs], sigmas[obs])

    def _pass_ok(self, index: IntArray) -> npt.NDArray[np.bool_]:
        """Whether the current pass of landmarks ``index`` confirms them for good."""
        hits, expected = self._run_hits[index], self._run_expected[index]
        ok: npt.NDArray[np.bool_] = (hits >= self.min_observations) & (hits >= self.min_pass_ratio * expected)
        return ok

    def _count_in_range(self, index: IntArray) -> None:
        """Count this frame for the landmarks in range; one out of range ``window_frames`` starts a new pass
        (the pass before confirms it for good if it matched it often enough)."""
        new_pass = self._last_in_range[index] < self._frame - self.window_frames
        self._confirmed[index[new_pass]] |= self._pass_ok(index[new_pass])
        self._run_hits[index[new_pass]] = 0
        self._run_expected[index[new_pass]] = 0
        self._run_expected[index] += 1
        self._expected[index] += 1
        self._last_in_range[index] = self._frame

    def _support(self, points: FloatArray) -> npt.NDArray[np.bool_]:
        """(C, P) whether pool ray p passes through candidate point c within its gate."""
        pool = self._pool
        delta = points[:, None, :] - pool.origins[None, :, :]
        dist = np.hypot(delta[..., 0], delta[..., 1])
        seen = np.arctan2(delta[..., 1], delta[..., 0])
        residual = np.abs(wrap(seen - pool.angles[None, :]))
        limit = np.sqrt(self.gate_sq) * pool.sigmas_at(np.arange(pool.angles.size)[None, :], dist)
        ok: npt.NDArray[np.bool_] = (residual <= limit) & (dist <= self.max_range_m) & (dist > 0.05)
        return ok

    def _candidates(self) -> FloatArray:
        """Crossings of this frame's pooled rays with older ones at a usable angle, (C, 2)."""
        pool = self._pool
        new = np.flatnonzero(pool.frames == self._frame)
        old = np.flatnonzero(pool.frames < self._frame)
        if new.size == 0 or old.size == 0:
            return np.zeros((0, 2))
        a1, a2 = pool.angles[new][:, None], pool.angles[old][None, :]
        u1 = np.stack([np.cos(a1), np.sin(a1)], axis=-1)
        u2 = np.stack([np.cos(a2), np.sin(a2)], axis=-1)
        cross = u1[..., 0] * u2[..., 1] - u1[..., 1] * u2[..., 0]
        usable = np.abs(cross) >= np.sin(0.25 * self.min_parallax_rad)
        w = pool.origins[old][None, :, :] - pool.origins[new][:, None, :]
        safe = np.where(usable, cross, 1.0)
        t1 = (w[..., 0] * u2[..., 1] - w[..., 1] * u2[..., 0]) / safe
        t2 = (w[..., 0] * u1[..., 1] - w[..., 1] * u1[..., 0]) / safe
        ok = usable & (t1 > 0.1) & (t2 > 0.1) & (t1 <= self.max_range_m) & (t2 <= self.max_range_m)
        points = pool.origins[new][:, None, :] + t1[..., None] * u1
        which, other = np.nonzero(ok)
        found = points[which, other]
        # A landmark's crossings with one new ray pile up in one place, one per older frame:
        # keep only places where enough older frames agree before the full support test.
        cell = np.floor(found / self._CELL_M).astype(np.int64)
        key = np.column_stack([which, cell])
        _, place = np.unique(key, axis=0, return_inverse=True)
        place = place.ravel()
        frames = pool.frames[old][other]
        pairs = np.unique(np.column_stack([place, frames]), axis=0)
        views = np.bincount(pairs[:, 0], minlength=int(place.max()) + 1 if place.size else 0)
        strong = views[place] >= self.min_views - 1
        if not strong.any():
            return np.zeros((0, 2))
        _, first = np.unique(place[strong], return_index=True)
        result: FloatArray = found[strong][first]
        return result

    def _initialise(self) -> int:
        points = self._candidates()
        born = 0
        # Support and range are computed once; a candidate tried leaves them, the rays of a landmark born too.
        support = self._support(points)
        origins = np.array([self._frame_origins[f] for f in sorted(self._frame_origins)])
        in_range = (np.hypot(*(points[:, None, :] - origins[None]).transpose(2, 0, 1)) <= self.max_range_m).sum(axis=1)
        while points.shape[0]:
            frames = np.unique(self._pool.frames)
            onehot = self._pool.frames[:, None] == frames[None, :]
            views = (support.astype(np.float64) @ onehot.astype(np.float64) > 0).sum(axis=1)
            views = np.where(views >= self.min_support_ratio * in_range, views, 0)
            best = int(np.argmax(views))
            if views[best] < self.min_views:
                break
            rays = self._one_per_frame(np.flatnonzero(support[best]), points[best])
            used = np.zeros(self._pool.angles.size, dtype=bool)
            used[rays] = True
            sigmas = self._pool.sigmas_at(rays, np.hypot(*(points[best] - self._pool.origins[rays]).T))
            expected = max(int(in_range[best]), rays.size)
            points, support = np.delete(points, best, axis=0), np.delete(support, best, axis=0)
            in_range = np.delete(in_range, best)
            try:
                tri = triangulate_bearings(self._pool.origins[rays], self._pool.angles[rays], sigmas)
            except PillarMappingError:
                continue
            limit = np.sqrt(self.gate_sq) * sigmas
            if tri.parallax_rad < self.min_parallax_rad or np.any(np.abs(tri.residuals_rad) > limit):
                continue
            ray_frames, ray_bearings, ray_sigmas = (self._pool.frames[rays], self._pool.bearings[rays],
                                                    self._pool.bearing_sigmas[rays])
            self._pool.keep(~used)
            support = support[:, ~used]
            if not self._duplicate(tri.mean, tri.cov):
                self._log.add_bearings(ray_frames, np.full(rays.size, len(self._means)), ray_bearings, ray_sigmas)
                self._append(tri.mean[None], tri.cov[None], np.array([rays.size]), np.array([expected]),
                             np.zeros(1, dtype=bool))
                born += 1
        return born

    def _one_per_frame(self, rays: IntArray, point: FloatArray) -> IntArray:
        """The best-fitting ray of each frame among ``rays``."""
        delta = point - self._pool.origins[rays]
        residual = np.abs(wrap(np.arctan2(delta[:, 1], delta[:, 0]) - self._pool.angles[rays]))
        order = np.lexsort((residual, self._pool.frames[rays]))
        first = np.ones(order.size, dtype=bool)
        first[1:] = self._pool.frames[rays][order][1:] != self._pool.frames[rays][order][:-1]
        return rays[order[first]]

    def _duplicate(self, mean: FloatArray, cov: FloatArray) -> bool:
        if not len(self._means):
            return False
        diff = self._means - mean
        total = self._covs + cov
        d2 = np.einsum("ni,nij,nj->n", diff, np.linalg.inv(total), diff)
        return bool(np.any(d2 <= 3.0 * self.gate_sq))
