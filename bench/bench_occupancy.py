"""Occupancy-grid integration speed: scans per second into a 5 cm grid, per ray-casting method.

Prints ``name value unit`` lines. Seeded scans of a 20 x 20 m room from random poses, with 5 % NaN
and 10 % no-return beams; the fraction of cells on which both methods agree is printed too (not timed).
Then the same room driven as a loop at 10 Hz with drifting odometry, integrated with and without
scan-to-map matching (one core).
"""

from __future__ import annotations

import math
import time

import numpy as np
from threadpoolctl import threadpool_limits

from services.occupancy_mapping import OccupancyGrid, RayCasting, ScanArrays, ScanMatcher
from services.occupancy_mapping.scanmatch import compose_poses
from shared.transforms import Pose2D

RESOLUTION_M = 0.05
HALF_ROOM_M = 10.0
N_SCANS = 200


def _room_ranges(x: float, y: float, yaw: float, angles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    b = angles + yaw
    c, s = np.cos(b), np.sin(b)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (HALF_ROOM_M - x) / c, (-HALF_ROOM_M - x) / c)
        ty = np.where(s > 0, (HALF_ROOM_M - y) / s, (-HALF_ROOM_M - y) / s)
    n = angles.size
    r = np.minimum(np.abs(tx), np.abs(ty)) + rng.normal(0.0, 0.01, n)
    r[rng.random(n) < 0.05] = np.nan
    r[rng.random(n) < 0.10] = np.inf
    return r


def _scans(n_beams: int, seed: int) -> tuple[np.ndarray, list[Pose2D], list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    angles = np.linspace(-math.pi, math.pi, n_beams, endpoint=False)
    poses, ranges = [], []
    for _ in range(N_SCANS):
        x, y = rng.uniform(-8.0, 8.0, 2)
        yaw = rng.uniform(-math.pi, math.pi)
        poses.append(Pose2D(float(x), float(y), float(yaw)))
        ranges.append(_room_ranges(float(x), float(y), float(yaw), angles, rng))
    return angles, poses, ranges


def _loop(n_beams: int, seed: int) -> tuple[np.ndarray, list[Pose2D], list[np.ndarray]]:
    """A 32 m loop through the room in 200 scans; odometry drifts to 0.5 m and 5 degrees by the end."""
    rng = np.random.default_rng(seed)
    angles = np.linspace(-math.pi, math.pi, n_beams, endpoint=False)
    odometry, ranges = [], []
    for i in range(N_SCANS):
        t = math.tau * i / N_SCANS
        true = Pose2D(6.0 * math.cos(t), 4.0 * math.sin(t), t + math.pi / 2)
        f = i / N_SCANS
        odometry.append(compose_poses(Pose2D(0.5 * f, -0.3 * f, math.radians(5.0) * f), true))
        ranges.append(_room_ranges(true.x_m, true.y_m, true.yaw_rad, angles, rng))
    return angles, odometry, ranges


def _run_matched(
    matching: bool, angles: np.ndarray, odometry: list[Pose2D], ranges: list[np.ndarray]
) -> float:
    grid = OccupancyGrid(resolution_m=RESOLUTION_M)
    matcher = ScanMatcher(max_range_m=25.0) if matching else None
    start = time.perf_counter()
    for i, (predicted, r) in enumerate(zip(odometry, ranges, strict=True)):
        scan = ScanArrays(r, angles, 0.1, 25.0, "laser", i)
        pose = predicted if matcher is None else matcher(grid, predicted, scan)
        grid.integrate(pose, r, angles, range_min_m=0.1, range_max_m=25.0, max_range_m=25.0)
    return len(odometry) / (time.perf_counter() - start)


def _run(
    method: RayCasting, angles: np.ndarray, poses: list[Pose2D], ranges: list[np.ndarray]
) -> tuple[float, np.ndarray]:
    grid = OccupancyGrid(resolution_m=RESOLUTION_M, ray_casting=method)
    grid.integrate(
        poses[0], ranges[0], angles, range_min_m=0.1, range_max_m=25.0, max_range_m=25.0
    )  # warm-up + growth
    start = time.perf_counter()
    for pose, r in zip(poses, ranges, strict=True):
        grid.integrate(pose, r, angles, range_min_m=0.1, range_max_m=25.0, max_range_m=25.0)
    return len(poses) / (time.perf_counter() - start), grid.occupancy()


def main() -> None:
    for n_beams in (720, 1080):
        angles, poses, ranges = _scans(n_beams, seed=n_beams)
        results = {method: _run(method, angles, poses, ranges) for method in RayCasting}
        for method, (rate, _) in results.items():
            print(f"occupancy_integrate_{method.value}_{n_beams}beams_5cm {rate:.1f} scans/s")
        a, b = (occ for _, occ in results.values())
        print(f"occupancy_method_agreement_{n_beams}beams {np.mean(a == b):.4f} fraction")
    with threadpool_limits(limits=1):
        for n_beams in (720, 1080):
            loop = _loop(n_beams, seed=n_beams)
            for matching in (False, True):
                rate = _run_matched(matching, *loop)
                name = "matched" if matching else "odometry"
                print(f"occupancy_integrate_{name}_loop_{n_beams}beams_5cm {rate:.1f} scans/s")


if __name__ == "__main__":
    main()
