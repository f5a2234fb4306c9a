"""Occupancy-grid integration speed: scans per second into a 5 cm grid, per ray-casting method.

Prints ``name value unit`` lines. Seeded scans of a 20 x 20 m room from random poses, with 5 % NaN
and 10 % no-return beams; the fraction of cells on which both methods agree is printed too (not timed).
"""

from __future__ import annotations

import math
import time

import numpy as np

from services.occupancy_mapping import OccupancyGrid, RayCasting
from shared.transforms import Pose2D

RESOLUTION_M = 0.05
HALF_ROOM_M = 10.0
N_SCANS = 200


def _scans(n_beams: int, seed: int) -> tuple[np.ndarray, list[Pose2D], list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    angles = np.linspace(-math.pi, math.pi, n_beams, endpoint=False)
    poses, ranges = [], []
    for _ in range(N_SCANS):
        x, y = rng.uniform(-8.0, 8.0, 2)
        yaw = rng.uniform(-math.pi, math.pi)
        b = angles + yaw
        c, s = np.cos(b), np.sin(b)
        with np.errstate(divide="ignore"):
            tx = np.where(c > 0, (HALF_ROOM_M - x) / c, (-HALF_ROOM_M - x) / c)
            ty = np.where(s > 0, (HALF_ROOM_M - y) / s, (-HALF_ROOM_M - y) / s)
        r = np.minimum(np.abs(tx), np.abs(ty)) + rng.normal(0.0, 0.01, n_beams)
        r[rng.random(n_beams) < 0.05] = np.nan
        r[rng.random(n_beams) < 0.10] = np.inf
        poses.append(Pose2D(float(x), float(y), float(yaw)))
        ranges.append(r)
    return angles, poses, ranges


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


if __name__ == "__main__":
    main()
