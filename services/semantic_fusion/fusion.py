"""Annotated scans in, semantic grid out: keyframes, loop closures, re-projection.

The state machine the live worker and offline runs share. Each scan attaches to the newest keyframe
(a new one starts when the camera has moved ``keyframe_distance_m`` or turned ``keyframe_angle_rad``
since the last), its points are kept in that keyframe's frame and added to the grid at the
keyframe's current pose estimate. When a keyframe is complete, its neighbourhood is matched against
earlier, far-in-time keyframes close by in space; accepted matches become loop closures, the pose
graph is re-optimised and every keyframe that moved is re-projected: its points are taken out of the
grid at their old cells and added at their new ones.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from services.semantic_fusion import se2
from services.semantic_fusion.classes import N_CLASSES, dynamic_columns
from services.semantic_fusion.errors import SemanticFusionError
from services.semantic_fusion.grid import SemanticGrid, evidence_weights
from services.semantic_fusion.inference import SemanticLayers, infer_labels, rasterise
from services.semantic_fusion.observations import ObservationStore
from services.semantic_fusion.pose_graph import PoseGraph
from services.semantic_fusion.scan import RangeScan, ScanObservation
from services.semantic_fusion.scan_matching import align_scans, match_scans

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class FusionSettings:
    """Tuning of :class:`SemanticFusion` (units in the names)."""

    resolution_m: float = 0.05
    max_confidence: float = 0.9
    dynamic_half_life_s: float = 20.0
    keyframe_distance_m: float = 0.5
    keyframe_angle_rad: float = 0.3
    loop_min_separation_keyframes: int = 40
    loop_candidate_radius_m: float = 4.0
    loop_search_radius_m: float = 2.0
    loop_search_angle_rad: float = 0.1
    loop_submap_keyframes: int = 20
    loop_min_inlier_fraction: float = 0.93
    loop_max_rmse_m: float = 0.06
    loop_min_points: int = 300
    loop_max_candidates: int = 2
    loop_max_ambiguity: float = 0.95
    loop_every_keyframes: int = 3
    loop_cooldown_keyframes: int = 10
    loop_max_residual_m: float = 0.15
    loop_max_residual_rad: float = 0.03
    loop_max_dropped: int = 3
    range_voxel_m: float = 0.05
    sequential_submap_keyframes: int = 10
    sequential_long_baseline_keyframes: int = 20
    sequential_long_baseline_every_keyframes: int = 4
    sequential_long_baseline_min_inlier_fraction: float = 0.5
    sequential_min_points: int = 100
    sequential_min_inlier_fraction: float = 0.8
    sequential_max_rmse_m: float = 0.03
    sequential_max_correspondence_m: float = 0.08
    sequential_information_scale: float = 0.1
    sequential_min_sigma_m: float = 1.0
    reproject_min_shift_m: float = 0.01
    max_point_range_m: float = 8.0

    def __post_init__(self) -> None:
        positive = {name: getattr(self, name) for name in (
            "resolution_m", "dynamic_half_life_s", "keyframe_distance_m", "keyframe_angle_rad",
            "loop_candidate_radius_m", "loop_max_rmse_m", "reproject_min_shift_m", "max_point_range_m",
            "range_voxel_m", "loop_max_residual_m", "loop_max_residual_rad", "sequential_max_rmse_m",
            "sequential_max_correspondence_m",
            "sequential_information_scale", "sequential_min_sigma_m", "sequential_long_baseline_min_inlier_fraction")}
        bad = {name: value for name, value in positive.items() if not (math.isfinite(value) and value > 0)}
        if bad:
            raise SemanticFusionError(f"settings must be positive and finite: {bad}")
        if self.loop_min_separation_keyframes < 1 or self.loop_submap_keyframes < 0 or min(
                self.loop_every_keyframes, self.loop_max_candidates,
                self.sequential_long_baseline_every_keyframes) < 1 or min(
                self.loop_cooldown_keyframes, self.sequential_submap_keyframes,
                self.sequential_long_baseline_keyframes, self.loop_max_dropped) < 0:
            raise SemanticFusionError("loop keyframe counts must be >= 1 (submaps, cooldown and drops >= 0)")


def voxel_centroids(points: npt.NDArray[np.float64], voxel_m: float) -> npt.NDArray[np.float64]:
    """One point per occupied ``voxel_m`` cell: the mean of the points in it.

    The mean, not the first point in scan order: that one sits at the same end of every cell along
    a surface, which biased every alignment of thinned scans the same way (a yaw drift of ~0.1 mrad
    per match that added up along an aisle).
    """
    cells = np.floor(points / voxel_m).astype(np.int64)
    _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    sums = np.zeros((counts.size, 2))
    np.add.at(sums, inverse, points)
    return sums / counts[:, None]


class SemanticFusion:
    """Fuses validated annotated scans of one robot into a :class:`SemanticGrid`.

    Parameters
    ----------
    settings : FusionSettings
        Tuning.
    pose_graph : PoseGraph, optional
        The graph to extend (default: a new one with default noise).
    detect_loops : bool
        Whether completed keyframes are matched against earlier ones.
    grid : SemanticGrid, optional
        The grid to write into (default: a new one from ``settings``). Several robots' fusions may
        share one: every update is a sum, so each re-projects its own points without disturbing the
        others'. Its resolution must be ``settings.resolution_m``.
    """

    def __init__(self, settings: FusionSettings | None = None, *, pose_graph: PoseGraph | None = None,
                 detect_loops: bool = True, grid: SemanticGrid | None = None) -> None:
        self.settings = settings or FusionSettings()
        self.graph = pose_graph or PoseGraph()
        if self.graph.n_keyframes:
            raise SemanticFusionError("the pose graph must start empty")
        if grid is not None and abs(grid.resolution_m - self.settings.resolution_m) > 1e-12:
            raise SemanticFusionError(
                f"grid resolution {grid.resolution_m} m differs from settings.resolution_m "
                f"{self.settings.resolution_m} m")
        self.grid = grid if grid is not None else SemanticGrid(
            resolution_m=self.settings.resolution_m, dynamic_half_life_s=self.settings.dynamic_half_life_s)
        self.store = ObservationStore()
        self.detect_loops = detect_loops
        self._keyframe_stamps_ns: list[int] = []
        self._range_points: dict[int, npt.NDArray[np.float32]] = {}
        self._last_stamp_ns: int | None = None
        self._dynamic = np.zeros(N_CLASSES, dtype=bool)
        self._dynamic[dynamic_columns()] = True

    @property
    def keyframe_stamps_ns(self) -> npt.NDArray[np.int64]:
        """Stamp of the scan that started each keyframe, (n,) int64 nanoseconds."""
        return np.asarray(self._keyframe_stamps_ns, dtype=np.int64)

    @property
    def last_stamp_ns(self) -> int | None:
        """Stamp of the newest scan taken, for the out-of-order check."""
        return self._last_stamp_ns

    @property
    def range_nbytes(self) -> int:
        """Memory held by the keyframes' range-scan points, bytes."""
        return sum(points.nbytes for points in self._range_points.values())

    def add_scan(self, scan: ScanObservation) -> int:
        """Take one scan; return the number of loop closures it led to (0 almost always)."""
        if self._last_stamp_ns is not None and scan.stamp_ns <= self._last_stamp_ns:
            raise SemanticFusionError(
                f"scan stamp {scan.stamp_ns} ns is not after the previous scan's {self._last_stamp_ns} ns")
        closures = 0
        n = self.graph.n_keyframes
        if not n or self._moved(self.graph.odometry_pose(n - 1), scan.camera_pose):
            if n and self.detect_loops:
                self._match_previous(n - 1)
                closures = self._close_loops(n - 1)
            self.graph.add_keyframe(scan.camera_pose)
            self.store.start_keyframe()
            self._keyframe_stamps_ns.append(scan.stamp_ns)
        key = self.graph.n_keyframes - 1
        local = se2.transform_points(se2.between(self.graph.odometry_pose(key), scan.camera_pose), scan.points_xy)
        world = se2.transform_points(self.graph.pose(key), local)
        weights = evidence_weights(scan.confidences, max_confidence=self.settings.max_confidence)
        rows = self.grid.rows_of(world)
        stamp_s = scan.stamp_ns * 1e-9
        self.grid.accumulate(rows, scan.columns, weights, scan.heights, np.full(rows.size, stamp_s))
        self.store.append(local, scan.columns, weights, scan.heights, stamp_s, rows)
        self._last_stamp_ns = scan.stamp_ns
        return closures

    def add_range_scan(self, scan: RangeScan) -> bool:
        """Attach a lidar scan to the newest keyframe, for scan matching; return whether it was kept.

        Each keyframe keeps the first range scan taken while it is the newest (not before its first
        annotated scan), its points moved into the keyframe's frame by odometry and thinned to one
        per ``range_voxel_m`` cell. Keyframes with a range scan are matched on those points (which
        see all around, further and whatever the labeller calls them) instead of the static-class
        annotated points. Feed a range scan before the first annotated scan stamped after it.
        """
        key = self.graph.n_keyframes - 1
        if (key < 0 or key in self._range_points or not scan.points_xy.shape[0]
                or scan.stamp_ns < self._keyframe_stamps_ns[key]):
            return False
        local = se2.transform_points(se2.between(self.graph.odometry_pose(key), scan.pose), scan.points_xy)
        self._range_points[key] = voxel_centroids(local, self.settings.range_voxel_m).astype(np.float32)
        return True

    def _moved(self, keyframe_pose: npt.NDArray[np.float64], pose: npt.NDArray[np.float64]) -> bool:
        step = se2.between(keyframe_pose, pose)
        return bool(math.hypot(step[0], step[1]) >= self.settings.keyframe_distance_m
                    or abs(step[2]) >= self.settings.keyframe_angle_rad)

    def _submap(self, centre: int, lo: int, hi: int) -> npt.NDArray[np.float64]:
        """Static-class points of keyframes ``lo..hi`` in keyframe ``centre``'s frame."""
        keys = np.arange(max(lo, 0), min(hi, self.graph.n_keyframes - 1) + 1)
        batch = self.store.batch(keys)
        static = ~self._dynamic[batch.columns]
        poses = self.graph.poses
        relative = se2.between(poses[centre], poses[keys])[np.searchsorted(keys, batch.keyframes)]
        xy = batch.xy.astype(np.float64)
        c, s = np.cos(relative[:, 2]), np.sin(relative[:, 2])
        out = np.stack([relative[:, 0] + c * xy[:, 0] - s * xy[:, 1], relative[:, 1] + s * xy[:, 0] + c * xy[:, 1]], 1)
        return np.asarray(out[static])

    def _match_previous(self, key: int) -> None:
        """Align keyframe ``key``'s points with the submap of the keyframes before it (and further back).

        An accepted alignment enters the graph as a between-factor with the alignment's information
        (scaled by ``sequential_information_scale`` for the correlation between neighbouring points),
        ``key``'s estimate moves to it and its points are re-projected. Directions the points leave
        open stay at odometry, through an odometry prior inside the alignment. With
        ``sequential_long_baseline_keyframes`` > 0 and a range scan on every
        ``sequential_long_baseline_every_keyframes``-th ``key``, a second alignment, against the
        range scans around that many keyframes back (accepted with
        ``sequential_long_baseline_min_inlier_fraction``, since part of what the lidar sees now was
        out of its range then), ties ``key``'s heading to them directly, so the chain's yaw error
        does not add up keyframe by keyframe. Only the heading: seen from the other side that far on,
        the same uprights give a translation the alignment's information overstates. The camera
        cone does not see that far back.
        """
        cfg = self.settings
        if key < 1 or cfg.sequential_submap_keyframes < 1:
            return
        if self._align(key, key - 1, key - cfg.sequential_submap_keyframes, key - 1, reseed=True,
                       min_inliers=cfg.sequential_min_inlier_fraction, heading_only=False):
            self.reproject([key])
        back = cfg.sequential_long_baseline_keyframes
        if (key in self._range_points and back > cfg.sequential_submap_keyframes
                and key % cfg.sequential_long_baseline_every_keyframes == 0
                and key - back - cfg.sequential_submap_keyframes // 2 >= 0):
            half = cfg.sequential_submap_keyframes // 2
            self._align(key, key - back, key - back - half, key - back + half, reseed=False,
                        min_inliers=cfg.sequential_long_baseline_min_inlier_fraction, heading_only=True)

    def _align(self, key: int, anchor: int, lo: int, hi: int, *, reseed: bool, min_inliers: float,
               heading_only: bool) -> bool:
        """Align ``key`` with keyframes ``lo..hi`` in ``anchor``'s frame; add the factor if accepted."""
        cfg = self.settings
        if key in self._range_points:
            source = self._range_points[key].astype(np.float64)
            target = self._range_submap(anchor, lo, hi)
        else:
            source = self._submap(key, key, key)
            target = self._submap(anchor, lo, hi)
        if min(source.shape[0], target.shape[0]) < cfg.sequential_min_points:
            return False
        odometry = se2.between(self.graph.odometry_pose(key - 1), self.graph.odometry_pose(key))
        guess = se2.compose(se2.between(self.graph.pose(anchor), self.graph.pose(key - 1)), odometry)
        sigma = self.graph.odometry_sigmas(key)
        try:
            alignment = align_scans(source, target, initial_pose=guess,
                                    prior_information=np.diag(1.0 / np.square(sigma)),
                                    max_correspondence_m=cfg.sequential_max_correspondence_m)
        except SemanticFusionError as exc:
            log.debug("keyframe %d not aligned with %d: %s", key, anchor, exc)
            return False
        if alignment.inlier_fraction < min_inliers or alignment.rmse_m > cfg.sequential_max_rmse_m:
            return False
        floor = 1.0 / cfg.sequential_min_sigma_m**2
        values, vectors = np.linalg.eigh(alignment.information * cfg.sequential_information_scale)
        information = (vectors * np.maximum(values, floor)) @ vectors.T
        if heading_only:  # the yaw marginal; the floor keeps the inverse finite on a lone straight wall
            information = np.diag([floor, floor, 1.0 / np.linalg.inv(information)[2, 2]])
        self.graph.add_scan_match(anchor, key, alignment.pose, (information + information.T) / 2, reseed=reseed)
        return True

    def _range_submap(self, centre: int, lo: int, hi: int) -> npt.NDArray[np.float64]:
        """Range-scan points of keyframes ``lo..hi`` (those that have one) in keyframe ``centre``'s frame."""
        keys = [k for k in range(max(lo, 0), hi + 1) if k in self._range_points]
        if not keys:
            return np.zeros((0, 2))
        poses = self.graph.poses
        relative = se2.between(poses[centre], poses[keys])
        return np.vstack([se2.transform_points(r, self._range_points[k]) for r, k in zip(relative, keys, strict=True)])

    def _close_loops(self, key: int) -> int:
        cfg = self.settings
        if key < cfg.loop_min_separation_keyframes or key % cfg.loop_every_keyframes:
            return 0
        if self.graph.loop_closures and key - self.graph.loop_closures[-1].to_key < cfg.loop_cooldown_keyframes:
            return 0
        poses = self.graph.poses
        earlier = poses[: key - cfg.loop_min_separation_keyframes + 1]
        distance = np.hypot(*(earlier[:, :2] - poses[key, :2]).T)
        candidates = np.argsort(distance)[: cfg.loop_max_candidates]
        candidates = candidates[distance[candidates] <= cfg.loop_candidate_radius_m]
        if not candidates.size:
            return 0
        source = self._submap(key, key - cfg.loop_submap_keyframes, key)
        if source.shape[0] < cfg.loop_min_points:
            return 0
        accepted = 0
        for j in candidates.tolist():
            target = self._submap(j, j - cfg.loop_submap_keyframes, j + cfg.loop_submap_keyframes)
            if target.shape[0] < cfg.loop_min_points:
                continue
            match = match_scans(source, target, initial_pose=se2.between(poses[j], poses[key]),
                                search_radius_m=cfg.loop_search_radius_m,
                                search_angle_rad=cfg.loop_search_angle_rad)
            if (match.inlier_fraction >= cfg.loop_min_inlier_fraction and match.rmse_m <= cfg.loop_max_rmse_m
                    and match.ambiguity <= cfg.loop_max_ambiguity):
                self.graph.add_loop_closure(j, key, match.pose)
                accepted += 1
                log.debug("loop closure %d -> %d: inliers %.2f rmse %.3f m ambiguity %.2f", j, key,
                          match.inlier_fraction, match.rmse_m, match.ambiguity)
        if not accepted:
            return 0
        before = self.graph.poses
        self.graph.optimise()
        dropped = 0
        while dropped < cfg.loop_max_dropped and (worst := self._worst_closure()) is not None:
            closure = self.graph.remove_loop_closure(worst)
            dropped += 1
            log.debug("loop closure %d -> %d dropped: the optimised graph disagrees with it", closure.from_key,
                      closure.to_key)
            self.graph.optimise()
        self._reproject_moved(before)
        return accepted

    def _worst_closure(self) -> int | None:
        """The loop closure the optimised graph disagrees with most, if any is beyond the residual limits."""
        cfg = self.settings
        if not self.graph.loop_closures:
            return None
        errors = np.array([self.graph.constraint_error(c) for c in self.graph.loop_closures])
        excess = np.maximum(np.hypot(errors[:, 0], errors[:, 1]) / cfg.loop_max_residual_m,
                            np.abs(errors[:, 2]) / cfg.loop_max_residual_rad)
        worst = int(np.argmax(excess))
        return worst if excess[worst] > 1.0 else None

    def add_pose_correction(self, stamp_ns: int, pose: npt.ArrayLike, *,
                            sigmas: tuple[float, float, float] = (0.05, 0.05, 0.02)) -> int:
        """Accept a corrected camera pose (map frame) the robot published for ``stamp_ns``.

        It becomes a prior on the keyframe nearest in time, the graph is re-optimised and moved
        keyframes are re-projected; returns the number of keyframes re-projected.
        """
        if not self._keyframe_stamps_ns:
            raise SemanticFusionError("no keyframes yet to correct")
        stamps = np.asarray(self._keyframe_stamps_ns)
        key = int(np.argmin(np.abs(stamps - stamp_ns)))
        self.graph.add_pose_prior(key, pose, sigmas=sigmas)
        return self._optimise_and_reproject()

    def _optimise_and_reproject(self) -> int:
        before = self.graph.poses
        self.graph.optimise()
        return self._reproject_moved(before)

    def _reproject_moved(self, before: npt.NDArray[np.float64]) -> int:
        """Re-project the keyframes whose estimates moved since ``before``; return how many."""
        step = se2.between(before, self.graph.poses)
        shift = np.hypot(step[:, 0], step[:, 1]) + np.abs(step[:, 2]) * self.settings.max_point_range_m
        moved = np.flatnonzero(shift >= self.settings.reproject_min_shift_m)
        self.reproject(moved)
        return int(moved.size)

    def reproject(self, keyframes: npt.ArrayLike | None = None) -> int:
        """Move the points of ``keyframes`` (default all) to their keyframes' current poses; return points moved."""
        keys = np.arange(self.graph.n_keyframes) if keyframes is None else np.asarray(keyframes, dtype=np.int64)
        if not keys.size:
            return 0
        batch = self.store.batch(keys)
        self.grid.accumulate(batch.rows, batch.columns, batch.weights, batch.heights, batch.stamps_s, sign=-1.0)
        pose = self.graph.poses[batch.keyframes]
        xy = batch.xy.astype(np.float64)
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        world = np.stack([pose[:, 0] + c * xy[:, 0] - s * xy[:, 1], pose[:, 1] + s * xy[:, 0] + c * xy[:, 1]], 1)
        rows = self.grid.rows_of(world)
        self.grid.accumulate(rows, batch.columns, batch.weights, batch.heights, batch.stamps_s)
        self.store.set_rows(keys, rows)
        return int(rows.size)

    def layers(self, *, now_ns: int | None = None, min_hits: float = 2.0, confident_entropy: float = 0.45,
               unconfident_entropy: float = 0.9, neighbour_radius_cells: int = 2,
               max_height_difference_m: float = 0.5) -> SemanticLayers:
        """Label and entropy rasters as of ``now_ns`` (default: the newest scan's stamp)."""
        now = now_ns if now_ns is not None else (self._last_stamp_ns or 0)
        cells = self.grid.cells(now_s=now * 1e-9)
        result = infer_labels(cells, min_hits=min_hits, confident_entropy=confident_entropy,
                              unconfident_entropy=unconfident_entropy,
                              neighbour_radius_cells=neighbour_radius_cells,
                              max_height_difference_m=max_height_difference_m)
        return rasterise(cells, result, resolution_m=self.grid.resolution_m)
