"""A 2-D pose graph of keyframes, optimised incrementally as nonlinear least squares with GTSAM's iSAM2.

Vertices are keyframe poses (x, y, yaw) in the map frame. Edges: odometry between consecutive
keyframes (noise growing with the distance driven), loop closures from scan matching (optionally
behind a Cauchy kernel; off by default, since the kernel also mutes the first, large correction
after a long drift, the one that matters most -- matches are vetted before they get here), and
absolute priors: the first keyframe's pose anchors the map frame, and corrected poses the robot
publishes enter as priors on their keyframes.

New keyframes and factors wait until :meth:`PoseGraph.optimise`, which hands them (and the loop
closures removed since) to iSAM2 in one update: only the part of the Bayes tree they touch is
re-eliminated and relinearised, not the whole trajectory as a batch solve would. Until then the
estimates stay as they were, so a caller can compare them before and after an optimisation.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import gtsam
import numpy as np
import numpy.typing as npt

from services.semantic_fusion import se2
from services.semantic_fusion.errors import SemanticFusionError


class Constraint(NamedTuple):
    """A relative-pose edge: pose of keyframe ``to_key`` in the frame of ``from_key`` (x, y m, yaw rad)."""

    from_key: int
    to_key: int
    relative: tuple[float, float, float]
    sigmas: tuple[float, float, float]


def _pose3(pose: npt.ArrayLike, what: str) -> npt.NDArray[np.float64]:
    p = np.asarray(pose, dtype=np.float64).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise SemanticFusionError(f"{what} must be 3 finite numbers (x, y, yaw), got {p.tolist()}")
    return p


def _sigmas(sigmas: tuple[float, float, float], what: str) -> gtsam.noiseModel.Diagonal:
    s = np.asarray(sigmas, dtype=np.float64)
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise SemanticFusionError(f"{what} sigmas must be 3 positive numbers, got {s.tolist()}")
    return gtsam.noiseModel.Diagonal.Sigmas(s)


class PoseGraph:
    """Keyframe poses with odometry, loop-closure and prior constraints.

    Parameters
    ----------
    odometry_sigma_per_m : float
        Translation noise of odometry per metre driven (fraction), at least ``min_sigma_m``.
    odometry_yaw_sigma_per_m : float
        Heading noise of odometry per metre driven, radians per metre, at least ``min_yaw_sigma_rad``.
    loop_sigmas : (float, float, float)
        Default loop-closure noise (x m, y m, yaw rad).
    loop_kernel : float, optional
        Cauchy kernel width on whitened loop-closure residuals; ``None`` for plain least squares.
    relinearize_threshold : float
        iSAM2 relinearises a keyframe once its update since its linearisation point exceeds this
        (metres and radians alike, in the keyframe's tangent space).
    """

    def __init__(
        self,
        *,
        odometry_sigma_per_m: float = 0.02,
        odometry_yaw_sigma_per_m: float = 0.005,
        min_sigma_m: float = 0.005,
        min_yaw_sigma_rad: float = 0.001,
        loop_sigmas: tuple[float, float, float] = (0.05, 0.05, 0.01),
        loop_kernel: float | None = None,
        relinearize_threshold: float = 0.001,
    ) -> None:
        if min(odometry_sigma_per_m, odometry_yaw_sigma_per_m, min_sigma_m, min_yaw_sigma_rad,
               1.0 if loop_kernel is None else loop_kernel, relinearize_threshold) <= 0:
            raise SemanticFusionError(
                "odometry noise, minimum sigmas, loop_kernel and relinearize_threshold must be positive")
        _sigmas(loop_sigmas, "loop_sigmas")
        self._per_m = (odometry_sigma_per_m, odometry_yaw_sigma_per_m)
        self._min = (min_sigma_m, min_yaw_sigma_rad)
        self._loop_sigmas = loop_sigmas
        self._kernel = loop_kernel
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(relinearize_threshold)
        params.relinearizeSkip = 1
        self._isam = gtsam.ISAM2(params)
        self._pending: dict[int, gtsam.NonlinearFactor] = {}  # by serial number, not yet in iSAM2
        self._n_factors = 0  # serial numbers handed out
        self._n_sent = 0  # keyframes whose values iSAM2 has
        self._isam_index: dict[int, int] = {}  # serial number -> iSAM2 factor index, loop closures only
        self._removed: list[int] = []  # iSAM2 indices of loop closures to take out at the next update
        self._odometry = np.zeros((64, 3))
        self._estimate = np.zeros((64, 3))
        self._n = 0
        self.loop_closures: list[Constraint] = []
        self._loop_factors: list[int] = []  # serial numbers, parallel to loop_closures
        self.n_scan_matches = 0

    def _add(self, factor: gtsam.NonlinearFactor) -> int:
        """Queue ``factor`` for the next iSAM2 update; return its serial number."""
        serial = self._n_factors
        self._pending[serial] = factor
        self._n_factors += 1
        return serial

    @property
    def n_keyframes(self) -> int:
        """Number of keyframes."""
        return self._n

    @property
    def poses(self) -> npt.NDArray[np.float64]:
        """Current pose estimates, (n, 3) float64 (x, y metres, yaw radians), a copy."""
        return self._estimate[: self._n].copy()

    @property
    def odometry_poses(self) -> npt.NDArray[np.float64]:
        """Keyframe poses as odometry gave them, (n, 3) float64, a copy."""
        return self._odometry[: self._n].copy()

    def pose(self, key: int) -> npt.NDArray[np.float64]:
        """Current estimate of keyframe ``key``, (3,) float64."""
        self._check_key(key)
        return np.array(self._estimate[key], dtype=np.float64)

    def odometry_pose(self, key: int) -> npt.NDArray[np.float64]:
        """Odometry pose of keyframe ``key``, (3,) float64."""
        self._check_key(key)
        return np.array(self._odometry[key], dtype=np.float64)

    def add_keyframe(self, odometry_pose: npt.ArrayLike) -> int:
        """Add a keyframe at ``odometry_pose`` (map frame as the robot estimates it); return its key.

        Its estimate continues from the previous keyframe's current estimate by the odometry step,
        so keyframes after a loop closure start where the closure put the trajectory.
        """
        pose = _pose3(odometry_pose, "odometry pose")
        key = self.n_keyframes
        if key == 0:
            anchor = _sigmas((self._min[0], self._min[0], self._min[1]), "anchor")
            self._add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*pose), anchor))
            estimate = pose
        else:
            step = se2.between(self._odometry[key - 1], pose)
            self._add(gtsam.BetweenFactorPose2(key - 1, key, gtsam.Pose2(*step),
                                               _sigmas(self._step_sigmas(step), "odometry")))
            estimate = se2.compose(self._estimate[key - 1], step)
        if key == self._odometry.shape[0]:
            self._odometry = np.vstack([self._odometry, np.zeros_like(self._odometry)])
            self._estimate = np.vstack([self._estimate, np.zeros_like(self._estimate)])
        self._odometry[key], self._estimate[key] = pose, estimate
        self._n = key + 1
        return key

    def _step_sigmas(self, step: npt.NDArray[np.float64]) -> tuple[float, float, float]:
        dist = math.hypot(step[0], step[1]) + 0.5 * abs(step[2])
        sig = max(self._per_m[0] * dist, self._min[0])
        return sig, sig, max(self._per_m[1] * dist, self._min[1])

    def odometry_sigmas(self, key: int) -> tuple[float, float, float]:
        """Noise (x m, y m, yaw rad) of the odometry step from keyframe ``key - 1`` to ``key``."""
        self._check_key(key)
        if key == 0:
            raise SemanticFusionError("keyframe 0 has no odometry step")
        return self._step_sigmas(se2.between(self._odometry[key - 1], self._odometry[key]))

    def _check_key(self, key: int) -> None:
        if not 0 <= key < self.n_keyframes:
            raise SemanticFusionError(f"keyframe {key} does not exist (have {self.n_keyframes})")

    def add_loop_closure(self, from_key: int, to_key: int, relative_pose: npt.ArrayLike, *,
                         sigmas: tuple[float, float, float] | None = None) -> None:
        """Constrain keyframe ``to_key``'s pose in ``from_key``'s frame to ``relative_pose``."""
        self._check_key(from_key)
        self._check_key(to_key)
        if from_key == to_key:
            raise SemanticFusionError(f"a loop closure needs two keyframes, got {from_key} twice")
        rel = _pose3(relative_pose, "relative pose")
        chosen = sigmas or self._loop_sigmas
        noise: gtsam.noiseModel.Base = _sigmas(chosen, "loop closure")
        if self._kernel is not None:
            noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(self._kernel), noise)
        self._loop_factors.append(self._add(gtsam.BetweenFactorPose2(from_key, to_key, gtsam.Pose2(*rel), noise)))
        self.loop_closures.append(Constraint(from_key, to_key, (rel[0], rel[1], rel[2]), chosen))

    def remove_loop_closure(self, index: int) -> Constraint:
        """Take loop closure ``index`` (position in :attr:`loop_closures`) out of the graph; return it.

        For a closure the optimised graph disagrees with. Estimates stay as they are until the next
        :meth:`optimise`, which takes the factor out of iSAM2 and moves them to the optimum without it.
        """
        if not 0 <= index < len(self.loop_closures):
            raise SemanticFusionError(f"loop closure {index} does not exist (have {len(self.loop_closures)})")
        serial = self._loop_factors.pop(index)
        if serial in self._pending:
            del self._pending[serial]
        else:
            self._removed.append(self._isam_index.pop(serial))
        return self.loop_closures.pop(index)

    def constraint_error(self, constraint: Constraint) -> npt.NDArray[np.float64]:
        """How far the current estimates are from ``constraint``: (x m, y m, yaw rad) in ``to_key``'s frame."""
        estimated = se2.between(self._estimate[constraint.from_key], self._estimate[constraint.to_key])
        return se2.between(estimated, np.asarray(constraint.relative))

    def add_scan_match(self, from_key: int, to_key: int, relative_pose: npt.ArrayLike,
                       information: npt.ArrayLike, *, reseed: bool = True) -> None:
        """Constrain ``to_key``'s pose in ``from_key``'s frame with a full (3, 3) ``information`` matrix.

        For matches between consecutive keyframes: the information (inverse covariance in ``to_key``'s
        tangent space, x, y, yaw) is what makes a match along a featureless aisle strong across it and
        in yaw but weak along it. When ``to_key`` is the newest keyframe and ``reseed`` is set, its
        estimate is re-seeded from ``from_key``'s through the match, so the keyframes that follow
        continue from the matched pose.
        """
        self._check_key(from_key)
        self._check_key(to_key)
        if from_key == to_key:
            raise SemanticFusionError(f"a scan match needs two keyframes, got {from_key} twice")
        rel = _pose3(relative_pose, "relative pose")
        info = np.asarray(information, dtype=np.float64)
        if info.shape != (3, 3) or not np.all(np.isfinite(info)) or not np.allclose(info, info.T) or np.min(
                np.linalg.eigvalsh(info)) <= 0:
            raise SemanticFusionError("scan match information must be a symmetric positive definite (3, 3) matrix")
        self._add(gtsam.BetweenFactorPose2(from_key, to_key, gtsam.Pose2(*rel),
                                           gtsam.noiseModel.Gaussian.Information(info)))
        self.n_scan_matches += 1
        if reseed and to_key == self._n - 1:
            self._estimate[to_key] = se2.compose(self._estimate[from_key], rel)

    def add_pose_prior(self, key: int, pose: npt.ArrayLike, *, sigmas: tuple[float, float, float]) -> None:
        """Constrain keyframe ``key`` to a corrected map-frame ``pose`` (as a robot's localiser publishes)."""
        self._check_key(key)
        self._add(gtsam.PriorFactorPose2(key, gtsam.Pose2(*_pose3(pose, "pose prior")),
                                         _sigmas(sigmas, "pose prior")))

    def optimise(self, *, max_iterations: int = 100) -> npt.NDArray[np.float64]:
        """Bring the queued keyframes, factors and removals into iSAM2 and iterate; return (n, 3) poses.

        New keyframes enter at their current estimates. After the update, further (Gauss-Newton)
        updates run until none relinearises a keyframe or ``max_iterations`` updates have run, so a
        large correction (a long loop closed, a closure dropped) converges as a batch solve would.
        """
        if self.n_keyframes == 0:
            return self.poses
        if max_iterations < 1:
            raise SemanticFusionError(f"max_iterations must be at least 1, got {max_iterations}")
        factors = gtsam.NonlinearFactorGraph()
        for factor in self._pending.values():
            factors.add(factor)
        initial = gtsam.Values()
        for key in range(self._n_sent, self._n):
            initial.insert(key, gtsam.Pose2(*self._estimate[key]))
        result = self._isam.update(factors, initial, self._removed)
        loops = set(self._loop_factors)
        for serial, index in zip(self._pending, result.getNewFactorsIndices(), strict=True):
            if serial in loops:
                self._isam_index[serial] = index
        self._pending.clear()
        self._removed = []
        self._n_sent = self._n
        for _ in range(max_iterations - 1):
            if not self._isam.update().getVariablesRelinearized():
                break
        estimate = gtsam.utilities.extractPose2(self._isam.calculateEstimate())
        self._estimate[: self._n] = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
        return self.poses
