"""Scoring against synthetic ground truth: detections per frame, mapped positions; drives and simulated bearings."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from services.pillar_mapping import FisheyeCamera, PillarDetections, detect_pillars
from services.pillar_mapping.synthetic import HallLayout, Scene, render_fisheye

FloatArray = npt.NDArray[np.float64]


class DetectionScore(NamedTuple):
    true_positives: int
    false_negatives: int
    false_positives: int
    errors_rad: list[float]

    @property
    def recall(self) -> float:
        return self.true_positives / max(self.true_positives + self.false_negatives, 1)

    @property
    def precision(self) -> float:
        return self.true_positives / max(self.true_positives + self.false_positives, 1)


def _dang(a: FloatArray, b: float) -> FloatArray:
    return np.abs((a - b + np.pi) % (2 * np.pi) - np.pi)


def optical_azimuths(points: FloatArray, pose: tuple[float, float, float]) -> FloatArray:
    """Azimuths in the default mount's optical frame of map points seen from ``pose``."""
    rel = points - np.asarray(pose[:2])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    bx, by = c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]
    return np.asarray(np.arctan2(-bx, -by))


def score_frame(
    found: PillarDetections,
    ids: npt.NDArray[np.int64],
    uprights: FloatArray,
    pose: tuple[float, float, float],
    *,
    radius_m: float,
    max_range_m: float = 8.0,
    min_pixels: int = 40,
) -> DetectionScore:
    """Recall over resolvable uprights in view (>= ``min_pixels`` visible, within ``max_range_m``);
    a detection is false if no visible upright lies within its half-width + 0.5 deg (at least 1 deg)."""
    count = np.bincount(ids[ids >= 0].ravel(), minlength=len(uprights))
    rho = np.hypot(*(uprights - np.asarray(pose[:2])).T)
    az = optical_azimuths(uprights, pose)
    half = np.arcsin(np.minimum(radius_m / rho, 1.0))
    visible = np.flatnonzero((count >= min_pixels) & (rho <= max_range_m))
    seen = np.flatnonzero(count >= 5)
    tp = fn = fp = 0
    errors = []
    for i in visible:
        others = seen[seen != i]
        if np.any(_dang(az[others], az[i]) <= half[i] + half[others] + np.deg2rad(0.5)):
            continue
        diff = _dang(found.bearings_rad, az[i])
        if diff.size and diff.min() <= max(np.deg2rad(0.5), half[i]):
            tp += 1
            errors.append(float(diff.min()))
        else:
            fn += 1
    for b in found.bearings_rad:
        diff = _dang(az[seen], b)
        if not np.any(diff <= np.maximum(half[seen] + np.deg2rad(0.5), np.deg2rad(1.0))):
            fp += 1
    return DetectionScore(tp, fn, fp, errors)


def aisle_poses(layout: HallLayout, rng: np.random.Generator, count: int) -> list[tuple[float, float, float]]:
    """Random poses near the centre lines of the aisles, any heading."""
    poses = []
    for _ in range(count):
        line = layout.aisles[rng.integers(len(layout.aisles))]
        xy = line[0] + rng.uniform(0.05, 0.95) * (line[1] - line[0]) + rng.normal(0.0, 0.3, 2)
        poses.append((float(xy[0]), float(xy[1]), float(rng.uniform(-np.pi, np.pi))))
    return poses


def detection_scores(
    camera: FisheyeCamera, scene: Scene, layout: HallLayout, rng: np.random.Generator, frames: int
) -> DetectionScore:
    total = DetectionScore(0, 0, 0, [])
    for pose in aisle_poses(layout, rng, frames):
        image, ids = render_fisheye(camera, scene, pose, rng)
        s = score_frame(detect_pillars(image, camera), ids, layout.uprights, pose, radius_m=scene.upright_radius_m)
        total = DetectionScore(
            total.true_positives + s.true_positives,
            total.false_negatives + s.false_negatives,
            total.false_positives + s.false_positives,
            total.errors_rad + s.errors_rad,
        )
    return total


def drive_aisles(layout: HallLayout, step_m: float, overshoot_m: float = 2.0) -> list[tuple[float, float, float]]:
    """Poses along each aisle's centre line, one pass, heading along the aisle."""
    poses = []
    for start, end in layout.aisles:
        length = float(np.hypot(*(end - start)))
        u = (end - start) / length
        yaw = float(np.arctan2(u[1], u[0]))
        for s in np.arange(-overshoot_m, length + overshoot_m, step_m):
            xy = start + s * u
            poses.append((float(xy[0]), float(xy[1]), yaw))
    return poses


def simulated_bearings(
    uprights: FloatArray,
    pose: tuple[float, float, float],
    rng: np.random.Generator,
    *,
    sigma_rad: float,
    max_range_m: float = 8.0,
    miss_rate: float = 0.05,
    clutter_rate: float = 0.2,
) -> FloatArray:
    """Vehicle-frame bearings to uprights in range with Gaussian noise, misses and random clutter."""
    rel = uprights - np.asarray(pose[:2])
    keep = (np.hypot(*rel.T) <= max_range_m) & (rng.random(len(rel)) >= miss_rate)
    b = np.arctan2(rel[keep, 1], rel[keep, 0]) - pose[2] + rng.normal(0.0, sigma_rad, int(keep.sum()))
    clutter = rng.uniform(-np.pi, np.pi, rng.poisson(clutter_rate))
    return np.concatenate([b, clutter])


def map_rmse(estimated: FloatArray, truth: FloatArray, *, gate_m: float = 0.5) -> tuple[float, int, int]:
    """(RMSE of matched positions, matched count, unmatched estimates) under one-to-one matching."""
    if len(estimated) == 0:
        return float("nan"), 0, 0
    d = np.hypot(*(estimated[:, None, :] - truth[None, :, :]).transpose(2, 0, 1))
    r, c = linear_sum_assignment(d)
    ok = d[r, c] <= gate_m
    return float(np.sqrt(np.mean(d[r, c][ok] ** 2))), int(ok.sum()), int(len(estimated) - ok.sum())
