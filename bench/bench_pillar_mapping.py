"""Pillar-mapping bench: detection on rendered fisheye frames, bearing-only mapping, rack-row fitting.

Prints ``name value unit`` lines. Run: ``.venv/bin/python bench/bench_pillar_mapping.py [--quick]``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from services.pillar_mapping import BearingOnlyMapper, default_mount, detect_pillars, fit_layout, vehicle_bearings
from services.pillar_mapping.evaluation import (
    DetectionScore,
    aisle_poses,
    drive_aisles,
    map_rmse,
    score_frame,
    simulated_bearings,
)
from services.pillar_mapping.synthetic import (
    HallLayout,
    default_camera,
    merge_layouts,
    noisy_landmarks,
    rack_region,
    rack_scene,
    render_fisheye,
)


def report(name: str, value: float, unit: str) -> None:
    print(f"{name} {value:.6g} {unit}", flush=True)


def bench_detection(frames: int, size_px: int) -> float:
    rng = np.random.default_rng(10)
    layout = rack_region(aisles=3, bays=10)
    scene = rack_scene(layout, rng)
    camera = default_camera(size_px=size_px)
    total = DetectionScore(0, 0, 0, [])
    spent = 0.0
    for pose in aisle_poses(layout, rng, frames):
        image, ids = render_fisheye(camera, scene, pose, rng)
        start = time.perf_counter()
        found = detect_pillars(image, camera)
        spent += time.perf_counter() - start
        s = score_frame(found, ids, layout.uprights, pose, radius_m=scene.upright_radius_m)
        total = DetectionScore(
            total.true_positives + s.true_positives,
            total.false_negatives + s.false_negatives,
            total.false_positives + s.false_positives,
            total.errors_rad + s.errors_rad,
        )
    tag = f"detect_{size_px}px"
    report(f"{tag}_uprights_in_view", total.true_positives + total.false_negatives, "count")
    report(f"{tag}_recall", 100 * total.recall, "%")
    report(f"{tag}_precision", 100 * total.precision, "%")
    report(f"{tag}_median_bearing_error", float(np.rad2deg(np.median(total.errors_rad))), "deg")
    report(f"{tag}_p95_bearing_error", float(np.rad2deg(np.percentile(total.errors_rad, 95))), "deg")
    report(f"{tag}_time_per_frame", 1000 * spent / frames, "ms")
    return float(np.percentile(total.errors_rad, 95))


def bench_mapping_rendered(size_px: int, step_m: float) -> None:
    rng = np.random.default_rng(20)
    layout = rack_region(aisles=2, bays=8)
    scene = rack_scene(layout, rng)
    camera = default_camera(size_px=size_px)
    mapper = BearingOnlyMapper()
    mount = default_mount()
    spent = 0.0
    poses = drive_aisles(layout, step_m)
    for pose in poses:
        image, _ = render_fisheye(camera, scene, pose, rng)
        start = time.process_time()
        found = detect_pillars(image, camera)
        mapper.observe(pose, vehicle_bearings(mount, found.bearings_rad), found.sigmas_rad)
        spent += time.process_time() - start
    rmse, matched, extra = map_rmse(mapper.reliable_landmarks().means, layout.uprights)
    report("map_rendered_frames", len(poses), "count")
    report("map_rendered_uprights_true", len(layout.uprights), "count")
    report("map_rendered_uprights_matched", matched, "count")
    report("map_rendered_landmarks_spurious", extra, "count")
    report("map_rendered_rmse", 100 * rmse, "cm")
    report("map_rendered_cpu_per_frame", 1000 * spent / len(poses), "ms")


def bench_mapping_simulated(sigma_rad: float) -> None:
    rng = np.random.default_rng(21)
    layout = rack_region(aisles=4, bays=20)
    mapper = BearingOnlyMapper()
    poses = drive_aisles(layout, 0.25)
    start = time.perf_counter()
    for pose in poses:
        b = simulated_bearings(layout.uprights, pose, rng, sigma_rad=sigma_rad)
        mapper.observe(pose, b, np.full(b.size, sigma_rad))
    spent = time.perf_counter() - start
    rmse, matched, extra = map_rmse(mapper.reliable_landmarks().means, layout.uprights)
    report("map_sim_bearing_sigma", float(np.rad2deg(sigma_rad)), "deg")
    report("map_sim_uprights_true", len(layout.uprights), "count")
    report("map_sim_uprights_matched", matched, "count")
    report("map_sim_landmarks_spurious", extra, "count")
    report("map_sim_rmse", 100 * rmse, "cm")
    report("map_sim_time_per_frame", 1000 * spent / len(poses), "ms")


def bench_rows(name: str, layout_fn: Callable[[], HallLayout], seeds: int) -> None:
    rows_ok = bins_found = bins_truth = invented = 0
    rows_truth = 0
    times = []
    cpu = []
    for seed in range(seeds):
        layout = layout_fn()
        landmarks, _ = noisy_landmarks(layout, np.random.default_rng(seed), sigma_m=0.03, missing_fraction=0.1)
        with threadpool_limits(1):
            start, start_cpu = time.perf_counter(), time.process_time()
            result = fit_layout(landmarks)
            times.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
        for r in range(len(layout.row_n)):
            pts = layout.uprights[layout.row_of == r]
            match = [
                row
                for row in result.rows
                if min(np.hypot(*(row.uprights[0] - pts[0])), np.hypot(*(row.uprights[0] - pts[-1]))) < 0.15
                and row.n == layout.row_n[r]
                and abs(row.d_m - layout.row_d[r]) < 0.01
            ]
            rows_ok += bool(match)
        rows_truth += len(layout.row_n)
        centres = np.array([b.centre for b in result.bins]).reshape(-1, 2)
        if len(centres):
            d_found, _ = cKDTree(centres).query(layout.bin_centres)
            d_truth, _ = cKDTree(layout.bin_centres).query(centres)
            bins_found += int((d_found <= 0.1).sum())
            invented += int((d_truth > 0.1).sum())
        bins_truth += len(layout.bin_centres)
    layout = layout_fn()
    ext = layout.uprights.max(axis=0) - layout.uprights.min(axis=0)
    report(f"{name}_uprights", len(layout.uprights), "count")
    report(f"{name}_extent_x", float(ext[0]), "m")
    report(f"{name}_extent_y", float(ext[1]), "m")
    report(f"{name}_rows_exact", 100 * rows_ok / rows_truth, "%")
    report(f"{name}_bins_found", 100 * bins_found / bins_truth, "%")
    report(f"{name}_bins_invented", invented, "count")
    report(f"{name}_fit_time_median", float(np.median(times)), "s")
    report(f"{name}_fit_time_max", float(np.max(times)), "s")
    report(f"{name}_fit_cpu_median", float(np.median(cpu)), "s")
    report(f"{name}_fit_cpu_max", float(np.max(cpu)), "s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer frames and seeds")
    parser.add_argument("--rows-only", action="store_true", help="only the row and bin fitting")
    parser.add_argument("--seeds", type=int, default=None, help="landmark draws per hall (default 5, quick 2)")
    args = parser.parse_args()
    frames = 8 if args.quick else 30
    seeds = args.seeds or (2 if args.quick else 5)
    if not args.rows_only:
        p95 = bench_detection(frames, 640)
        bench_detection(frames, 480)
        bench_mapping_simulated(max(p95, float(np.deg2rad(0.1))))
        bench_mapping_rendered(480, 0.5 if args.quick else 0.25)
    bench_rows("hall_one_region", lambda: rack_region(aisles=19, bays=26), seeds)
    bench_rows(
        "hall_two_regions",
        lambda: merge_layouts(
            rack_region(aisles=19, bays=26),
            rack_region(origin_xy_m=(150.0, 0.0), theta_rad=np.deg2rad(30), aisles=5, bays=12, bay_pitch_m=3.6),
        ),
        seeds,
    )


if __name__ == "__main__":
    main()
