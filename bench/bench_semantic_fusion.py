"""Semantic fusion: accuracy, loop closure, throughput, re-projection and memory on synthetic halls.

Prints ``name value unit`` lines. Seeded synthetic warehouses (services.semantic_fusion.synthetic):
a 60 x 30 m hall for accuracy over seeds (inference vs raw arg-max, true poses and SLAM poses), and
a 250 x 72 m hall at 5 cm driven end to end for throughput (one core), re-projection of 1000
keyframes and memory. ``--png-dir DIR`` also writes before/after loop-closure label images.

Run: ``.venv/bin/python bench/bench_semantic_fusion.py [--png-dir docs]``
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

import numpy as np
from PIL import Image
from threadpoolctl import threadpool_limits

from services.semantic_fusion import (
    DYNAMIC_CLASSES,
    FusionSettings,
    SemanticFusion,
    absolute_trajectory_error,
    infer_labels,
    label_accuracy,
    rasterise,
    render_labels,
    se2,
)
from services.semantic_fusion import synthetic as syn
from services.semantic_fusion.scan import ScanObservation, observation_from_message
from shared import messages

RESOLUTION_M = 0.05
CONFIDENT_ENTROPY = 0.45
UNCONFIDENT_ENTROPY = 0.9


def _keyframe_truth(fusion: SemanticFusion, run: syn.SimulatedRun) -> np.ndarray:
    stamps = np.array([s.stamp_ns for s in run.scans])
    return run.true_poses[np.searchsorted(stamps, fusion.keyframe_stamps_ns)]


def _accuracy(fusion: SemanticFusion, truth: np.ndarray) -> tuple[float, float, float]:
    cells = fusion.grid.cells(now_s=(fusion.last_stamp_ns or 0) * 1e-9)
    result = infer_labels(cells, confident_entropy=CONFIDENT_ENTROPY, unconfident_entropy=UNCONFIDENT_ENTROPY)
    inferred = label_accuracy(rasterise(cells, result, resolution_m=RESOLUTION_M), truth, exclude=DYNAMIC_CLASSES)
    raw = label_accuracy(rasterise(cells, result._replace(labels=result.raw_labels), resolution_m=RESOLUTION_M),
                         truth, exclude=DYNAMIC_CLASSES)
    return inferred.fraction, raw.fraction, inferred.spurious / max(inferred.cells, 1)


def _feed(fusion: SemanticFusion, run: syn.SimulatedRun, *, lidar: bool) -> float:
    """Feed a run (annotated scans, and range scans when ``lidar``); return CPU seconds."""
    ranges = {r.stamp_ns: r for r in run.range_scans} if lidar else {}
    start = time.process_time()
    for scan in run.scans:
        fusion.add_scan(scan)
        if scan.stamp_ns in ranges:
            fusion.add_range_scan(ranges[scan.stamp_ns])
    return time.process_time() - start


def _closure_errors(fusion: SemanticFusion, truth_kf: np.ndarray) -> np.ndarray:
    """Position error (m) of each accepted loop closure's relative pose against the true relative pose."""
    closures = fusion.graph.loop_closures
    if not closures:
        return np.zeros(0)
    frm = np.array([c.from_key for c in closures])
    to = np.array([c.to_key for c in closures])
    error = se2.between(se2.between(truth_kf[frm], truth_kf[to]), np.array([c.relative for c in closures]))
    return np.hypot(error[:, 0], error[:, 1])


def accuracy(png_dir: Path | None) -> None:
    """Small halls over seeds: label accuracy with true, odometry and SLAM poses; ATE before/after.

    SLAM runs twice: on the annotated scans alone (static-class points for matching) and with the
    robot's lidar (541 beams over 270 degrees, 20 m, 1 cm noise, every other frame) for matching.
    """
    for seed in range(3):
        warehouse = syn.make_warehouse(length_m=60.0, width_m=30.0, seed=seed)
        run = syn.simulate_run(warehouse, seed=100 + seed, lidar_beams=541)
        truth = syn.truth_labels(warehouse, resolution_m=RESOLUTION_M)
        exact = SemanticFusion(FusionSettings(resolution_m=RESOLUTION_M), detect_loops=False)
        for scan, pose in zip(run.scans, run.true_poses, strict=True):
            exact.add_scan(scan._replace(camera_pose=pose))
        inferred, raw, spurious = _accuracy(exact, truth)
        print(f"accuracy_true_poses_seed{seed}_inferred {100 * inferred:.2f} %")
        print(f"accuracy_true_poses_seed{seed}_raw_argmax {100 * raw:.2f} %")
        print(f"scans_seed{seed} {len(run.scans)} count")
        for tag, loops, lidar in (("odometry", False, False), ("slam", True, False), ("slam_lidar", True, True)):
            fusion = SemanticFusion(FusionSettings(resolution_m=RESOLUTION_M), detect_loops=loops)
            cpu = _feed(fusion, run, lidar=lidar)
            inferred, raw, spurious = _accuracy(fusion, truth)
            truth_kf = _keyframe_truth(fusion, run)
            ate = absolute_trajectory_error(fusion.graph.poses, truth_kf)
            print(f"accuracy_{tag}_seed{seed}_inferred {100 * inferred:.2f} %")
            print(f"accuracy_{tag}_seed{seed}_raw_argmax {100 * raw:.2f} %")
            print(f"spurious_cells_{tag}_seed{seed} {100 * spurious:.1f} %")
            print(f"ate_{tag}_seed{seed} {ate:.3f} m")
            print(f"rate_{tag}_seed{seed} {len(run.scans) / cpu:.0f} scans/s (CPU)")
            if loops:
                errors = _closure_errors(fusion, truth_kf)
                print(f"loop_closures_{tag}_seed{seed} {len(fusion.graph.loop_closures)} count")
                print(f"loop_closure_error_rms_{tag}_seed{seed} {np.sqrt(np.mean(errors**2)):.3f} m")
                print(f"sequential_matches_{tag}_seed{seed} {fusion.graph.n_scan_matches} of "
                      f"{fusion.graph.n_keyframes - 1} keyframes")
                tail = slice(-len(fusion.graph.poses) // 5, None)  # the revisited stretch at the end
                print(f"ate_revisited_odometry_seed{seed} "
                      f"{absolute_trajectory_error(fusion.graph.odometry_poses[tail], truth_kf[tail]):.3f} m")
                print(f"ate_revisited_{tag}_seed{seed} "
                      f"{absolute_trajectory_error(fusion.graph.poses[tail], truth_kf[tail]):.3f} m")
                print(f"max_position_error_{tag}_seed{seed} "
                      f"{np.max(np.hypot(*(fusion.graph.poses[:, :2] - truth_kf[:, :2]).T)):.3f} m")
            if png_dir is not None and seed == 0:
                layers = fusion.layers(confident_entropy=CONFIDENT_ENTROPY, unconfident_entropy=UNCONFIDENT_ENTROPY)
                image = render_labels(layers.labels, scale=1)
                name = {"odometry": "semantic_fusion_before_loop_closure.png",
                        "slam": "semantic_fusion_after_loop_closure.png",
                        "slam_lidar": "semantic_fusion_after_loop_closure_lidar.png"}[tag]
                Image.fromarray(image).save(png_dir / name, optimize=True)
        if png_dir is not None and seed == 0:
            truth_image = render_labels(np.where(truth > 0, truth, 0).astype(np.uint8), scale=1)
            Image.fromarray(truth_image).save(png_dir / "semantic_fusion_truth.png", optimize=True)


def _message(scan: ScanObservation, names: list[str]) -> bytes:
    cls = messages.message_class
    stamp = cls("builtin_interfaces/msg/Time")(sec=scan.stamp_ns // 10**9, nanosec=scan.stamp_ns % 10**9)
    x, y, yaw = scan.camera_pose
    pose = cls("geometry_msgs/msg/Pose")(
        position=cls("geometry_msgs/msg/Point")(x=x, y=y, z=1.0),
        orientation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2)))
    ranges = np.hypot(scan.points_xy[:, 0], scan.points_xy[:, 1]).astype(np.float32)
    bearings = np.arctan2(scan.points_xy[:, 1], scan.points_xy[:, 0]).astype(np.float32)
    msg = cls(messages.ANNOTATED_SCAN)(
        header=cls("std_msgs/msg/Header")(stamp=stamp, frame_id="camera"), camera_pose=pose, bearings=bearings,
        ranges=ranges, heights=scan.heights, labels=scan.columns.astype(np.uint8), confidences=scan.confidences,
        class_names=names)
    return messages.serialize(msg, messages.ANNOTATED_SCAN)


def hall() -> None:
    """250 x 72 m hall at 5 cm: throughput, re-projection of 1000 keyframes, memory.

    Scans carry their true camera poses here (as after perfect SLAM), so the grid covers the hall's
    real extent; the odometry of a 6 km drive would smear it over a much larger box.
    """
    start = time.perf_counter()
    warehouse = syn.make_warehouse(length_m=250.0, width_m=72.0, n_forklifts=6, n_humans=10, seed=7)
    simulated = syn.simulate_run(warehouse, seed=8, n_cones=160)
    run = simulated._replace(scans=[s._replace(camera_pose=p) for s, p in zip(simulated.scans, simulated.true_poses,
                                                                            strict=True)])
    print(f"hall_simulation_time {time.perf_counter() - start:.1f} s")
    n_points = sum(s.columns.size for s in run.scans)
    print(f"hall_scans {len(run.scans)} count")
    print(f"hall_points_per_scan {n_points / len(run.scans):.1f} points")
    fusion = SemanticFusion(FusionSettings(resolution_m=RESOLUTION_M), detect_loops=False)
    start = time.perf_counter()
    for scan in run.scans:
        fusion.add_scan(scan)
    elapsed = time.perf_counter() - start
    print(f"hall_integrate_rate {len(run.scans) / elapsed:.0f} scans/s")
    inferred, raw, _ = _accuracy(fusion, syn.truth_labels(warehouse, resolution_m=RESOLUTION_M))
    print(f"hall_accuracy_true_poses_inferred {100 * inferred:.2f} %")
    print(f"hall_accuracy_true_poses_raw_argmax {100 * raw:.2f} %")
    tracemalloc.start()
    traced = SemanticFusion(FusionSettings(resolution_m=RESOLUTION_M), detect_loops=False)
    for scan in run.scans:
        traced.add_scan(scan)
    current, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    del traced
    print(f"hall_grid_cells {fusion.grid.n_cells} cells")
    print(f"hall_memory_grid {fusion.grid.nbytes / 2**20:.1f} MB")
    print(f"hall_memory_observations {fusion.store.nbytes / 2**20:.1f} MB")
    print(f"hall_memory_traced {current / 2**20:.1f} MB")
    payloads = [_message(s, list(syn.CLASS_NAMES)) for s in run.scans[:3000]]
    decoded = SemanticFusion(FusionSettings(resolution_m=RESOLUTION_M), detect_loops=False)
    start = time.perf_counter()
    for payload in payloads:
        msg = messages.deserialize(payload, messages.ANNOTATED_SCAN)
        decoded.add_scan(observation_from_message(msg, previous_stamp_ns=decoded.last_stamp_ns))
    print(f"hall_decode_validate_integrate_rate {len(payloads) / (time.perf_counter() - start):.0f} scans/s")
    keys = np.arange(fusion.graph.n_keyframes - 1000, fusion.graph.n_keyframes)
    n_moved = int(fusion.store.batch(keys).rows.size)
    start = time.perf_counter()
    fusion.reproject(keys)
    print(f"hall_reproject_1000_keyframes {time.perf_counter() - start:.3f} s ({n_moved} points)")
    start = time.perf_counter()
    shift = fusion.graph.odometry_poses[-1] + np.array([0.5, -0.3, 0.02])
    moved = fusion.add_pose_correction(int(fusion.keyframe_stamps_ns[-1]), shift, sigmas=(0.01, 0.01, 0.002))
    print(f"hall_correction_optimise_reproject {time.perf_counter() - start:.3f} s ({moved} keyframes)")
    start = time.perf_counter()
    layers = fusion.layers(confident_entropy=CONFIDENT_ENTROPY, unconfident_entropy=UNCONFIDENT_ENTROPY)
    rows, cols = layers.labels.shape
    print(f"hall_inference {time.perf_counter() - start:.3f} s ({cols} x {rows} cells)")


def hall_slam(n_scans: int) -> None:
    """The 250 x 72 m hall's first ``n_scans`` scans with drifting odometry: SLAM cost and ATE, one core."""
    warehouse = syn.make_warehouse(length_m=250.0, width_m=72.0, n_forklifts=6, n_humans=10, seed=7)
    run = syn.simulate_run(warehouse, seed=8, n_cones=160, lidar_beams=541, max_scans=n_scans)
    print(f"hall_slam_scans {len(run.scans)} count")
    long_baseline = FusionSettings().sequential_long_baseline_keyframes
    for tag, lidar, back in (("slam", False, long_baseline), ("slam_lidar", True, long_baseline),
                             ("slam_lidar_no_long_baseline", True, 0)):
        fusion = SemanticFusion(FusionSettings(resolution_m=RESOLUTION_M, sequential_long_baseline_keyframes=back))
        cpu = _feed(fusion, run, lidar=lidar)
        truth_kf = _keyframe_truth(fusion, run)
        print(f"hall_{tag}_rate {len(run.scans) / cpu:.0f} scans/s (CPU, {fusion.graph.n_keyframes} keyframes, "
              f"{len(fusion.graph.loop_closures)} loop closures)")
        print(f"hall_{tag}_ate {absolute_trajectory_error(fusion.graph.poses, truth_kf):.3f} m (odometry "
              f"{absolute_trajectory_error(fusion.graph.odometry_poses, truth_kf):.3f} m)")
        if tag == "slam_lidar":
            per_keyframe = fusion.range_nbytes / fusion.graph.n_keyframes
            print(f"hall_range_points_memory {fusion.range_nbytes / 2**20:.1f} MB "
                  f"({per_keyframe / 1024:.1f} KB a keyframe)")
        start = time.process_time()
        fusion.graph.optimise()
        print(f"hall_{tag}_optimise {time.process_time() - start:.3f} s CPU (iSAM2 update, {fusion.graph.n_keyframes} "
              f"keyframes, {fusion.graph.n_scan_matches} sequential matches)")
        poses = fusion.graph.poses  # a loop closed across the whole drive, 20 cm and 0.5 degrees off the estimate
        fusion.graph.add_loop_closure(0, len(poses) - 1, se2.between(poses[0], poses[-1]) + np.array([0.2, 0.0, 0.009]))
        start = time.process_time()
        fusion.graph.optimise()
        print(f"hall_{tag}_long_loop_optimise {time.process_time() - start:.3f} s CPU (closure 0 -> "
              f"{len(poses) - 1})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--png-dir", type=Path, default=None)
    parser.add_argument("--skip-hall", action="store_true")
    parser.add_argument("--only-hall", action="store_true")
    parser.add_argument("--hall-slam-scans", type=int, default=8000)
    parser.add_argument("--skip-hall-grid", action="store_true", help="of the big hall, run only the SLAM part")
    args = parser.parse_args()
    with threadpool_limits(1):
        if not args.only_hall:
            accuracy(args.png_dir)
        if not args.skip_hall:
            if not args.skip_hall_grid:
                hall()
            hall_slam(args.hall_slam_scans)


if __name__ == "__main__":
    main()
