"""Pillar-mapping bench: detection on rendered fisheye frames, bearing-only mapping (with and without
localisation noise), rack-row and bin fitting on simulated halls, and fits of a partly surveyed hall.

Prints ``name value unit`` lines. Run:
``PYTHONPATH=. .venv/bin/python bench/bench_pillar_mapping.py [--quick] [--rows-only] [--seeds N] [--sim-survey]``.
``--sim-survey`` also records the simulator's demo survey (photo-textured fisheye, about 3 minutes) and maps it;
``--cli-only`` times just ``aisle racks fit`` as a user runs it (a fresh process: start-up, imports, fit, file) on a
4,680-upright hall turned 7 degrees, and ``aisle --help``.
"""

from __future__ import annotations

import argparse
import copy
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from services.pillar_mapping import (
    BearingOnlyMapper,
    RackRow,
    default_mount,
    detect_pillars,
    fit_landmark_map,
    fit_layout,
    hough_pairs,
    vehicle_bearings,
)
from services.pillar_mapping.evaluation import (
    DetectionScore,
    aisle_poses,
    drive_aisles,
    map_rmse,
    score_frame,
    simulated_bearings,
)
from services.pillar_mapping.landmark_io import write_landmarks_csv
from services.pillar_mapping.synthetic import (
    HallLayout,
    default_camera,
    merge_layouts,
    rack_region,
    rack_scene,
    render_fisheye,
)
from services.simulator import hall_layout, load_world, world_from_layout
from services.simulator.world import World

FloatArray = npt.NDArray[np.float64]

POSE_NOISE = {"pose_1cm_0.2deg": (0.01, 0.2), "pose_2cm_0.3deg": (0.02, 0.3), "pose_3cm_0.5deg": (0.03, 0.5)}
"""Localisation error levels (position std, heading std in degrees), applied as a slowly varying error."""
POSE_CORRELATION_FRAMES = 10.0
"""Frames over which the localisation error decorrelates (5 s at the 2 Hz fisheye rate)."""
ODOMETRY_SCALE_STD, ODOMETRY_YAW_BIAS_STD_RAD_PER_M = 0.01, 0.002
"""Wheel odometry as the simulator drifts it: a constant scale error and a gyro bias (per metre at 1 m/s)."""
ODOMETRY_WHITE = (0.001, 0.0005)
"""White noise per step, metres and radians."""

Frame = tuple[tuple[float, float, float], FloatArray, FloatArray, tuple[float, float, float] | None]
"""(true sensor pose, vehicle-frame bearings, their stds, odometry sensor pose or None to drift one)."""


def report(name: str, value: float, unit: str) -> None:
    print(f"{name} {value:.6g} {unit}", flush=True)


def pose_errors(count: int, rng: np.random.Generator, sigma_m: float, sigma_deg: float) -> FloatArray:
    """(count, 3) localisation errors: a first-order Gauss-Markov process with the given stds."""
    a = math.exp(-1.0 / POSE_CORRELATION_FRAMES)
    scale = np.array([sigma_m, sigma_m, math.radians(sigma_deg)])
    out = np.zeros((count, 3))
    x = rng.normal(0.0, 1.0, 3) * scale
    for k in range(count):
        x = a * x + math.sqrt(1 - a * a) * rng.normal(0.0, 1.0, 3) * scale
        out[k] = x
    return out


def _relative(a: FloatArray, b: FloatArray) -> FloatArray:
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    d = b[:, :2] - a[:, :2]
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                            np.angle(np.exp(1j * (b[:, 2] - a[:, 2])))])


def drifting_odometry(poses: FloatArray, rng: np.random.Generator) -> FloatArray:
    """(n, 3) odometry poses: the true steps between ``poses`` with a constant scale error, a heading
    bias per metre and white noise, integrated from the first pose (drift grows without bound)."""
    steps = _relative(poses[:-1], poses[1:])
    distance = np.hypot(steps[:, 0], steps[:, 1])
    scale = 1.0 + rng.normal(0.0, ODOMETRY_SCALE_STD)
    bias = rng.normal(0.0, ODOMETRY_YAW_BIAS_STD_RAD_PER_M)
    noisy = np.column_stack([steps[:, :2] * scale + rng.normal(0.0, ODOMETRY_WHITE[0], (len(steps), 2)),
                             steps[:, 2] + bias * distance + rng.normal(0.0, ODOMETRY_WHITE[1], len(steps))])
    out = np.zeros_like(poses)
    out[0] = poses[0]
    for k, (dx, dy, dyaw) in enumerate(noisy):
        c, s = math.cos(out[k, 2]), math.sin(out[k, 2])
        out[k + 1] = (out[k, 0] + c * dx - s * dy, out[k, 1] + s * dx + c * dy, out[k, 2] + dyaw)
    return out


def pose_cov(sigma_m: float, sigma_deg: float) -> FloatArray | None:
    return np.diag([sigma_m**2, sigma_m**2, math.radians(sigma_deg) ** 2]) if sigma_m > 0 else None


def bench_detection(frames: int, size_px: int) -> float:
    rng = np.random.default_rng(10)
    layout = rack_region(aisles=3, bays=10)
    scene = rack_scene(layout, rng)
    camera = default_camera(size_px=size_px)
    total = DetectionScore(0, 0, 0, [])
    spent = 0.0
    for pose in aisle_poses(layout, rng, frames):
        image, ids = render_fisheye(camera, scene, pose, rng)
        start = time.process_time()
        found = detect_pillars(image, camera)
        spent += time.process_time() - start
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
    report(f"{tag}_cpu_per_frame", 1000 * spent / frames, "ms")
    return float(np.percentile(total.errors_rad, 95))


def _map(frames: list[Frame], truth: FloatArray, tag: str, *, seeds: int, smooth_every: int) -> None:
    """Map the frames with exact poses, then with each localisation noise level: the EKF alone
    (``_rmse``; ``_rmse_within_20cm`` over the matches within 20 cm only), and with poses and landmarks
    smoothed with odometry and re-associated every ``smooth_every`` frames (10 s of driving, as the worker
    does every ``store_period_s``) and at the end (``_smoothed_rmse``)."""
    cases = {"known_pose": (0.0, 0.0), **POSE_NOISE}
    true_poses = np.array([f[0] for f in frames])
    for case, (sigma_m, sigma_deg) in cases.items():
        stats: dict[str, list[float]] = {}
        for seed in range(seeds if sigma_m > 0 else 1):
            rng = np.random.default_rng(100 + seed)
            errors = pose_errors(len(frames), rng, sigma_m, sigma_deg)
            drifted = drifting_odometry(true_poses, rng)
            cov = pose_cov(sigma_m, sigma_deg)
            for smoothed in (False, True):
                mapper = BearingOnlyMapper()
                spent, calls = 0.0, 0
                for k, ((pose, bearings, sigmas, odometry), error, odo) in enumerate(
                        zip(frames, errors, drifted, strict=True), start=1):
                    mapper.observe(tuple(np.asarray(pose) + error), bearings, sigmas, pose_cov=cov,
                                   odometry_pose=odometry if odometry is not None else tuple(odo))
                    if smoothed and (k % smooth_every == 0 or k == len(frames)):
                        start = time.process_time()
                        mapper.smooth()
                        spent, calls = spent + time.process_time() - start, calls + 1
                prefix = "smoothed_" if smoothed else ""
                means = mapper.reliable_landmarks().means
                for name, value in zip(("rmse", "uprights_matched", "landmarks_spurious"), map_rmse(means, truth),
                                       strict=True):
                    stats.setdefault(prefix + name, []).append(value)
                stats.setdefault(prefix + "rmse_within_20cm", []).append(map_rmse(means, truth, gate_m=0.2)[0])
                if smoothed:
                    stats.setdefault("smooth_cpu_per_call", []).append(spent / calls)
                    stats.setdefault("smooth_cpu_total", []).append(spent)
        for name, values in stats.items():
            scale, unit = (100.0, "cm") if "rmse" in name else (1.0, "s" if "cpu" in name else "count")
            report(f"{tag}_{case}_{name}", scale * float(np.mean(values)), unit)
            if "rmse" in name:
                report(f"{tag}_{case}_{name}_max", scale * float(np.max(values)), unit)


def bench_mapping_simulated(sigma_rad: float, seeds: int) -> None:
    rng = np.random.default_rng(21)
    layout = rack_region(aisles=4, bays=20)
    frames: list[Frame] = []
    for pose in drive_aisles(layout, 0.25):
        b = simulated_bearings(layout.uprights, pose, rng, sigma_rad=sigma_rad)
        frames.append((pose, b, np.full(b.size, sigma_rad), None))
    report("map_sim_bearing_sigma", float(np.rad2deg(sigma_rad)), "deg")
    report("map_sim_uprights_true", len(layout.uprights), "count")
    report("map_sim_frames", len(frames), "count")
    start = time.process_time()
    mapper = BearingOnlyMapper()
    for pose, b, s, _ in frames:
        mapper.observe(pose, b, s)
    report("map_sim_cpu_per_frame", 1000 * (time.process_time() - start) / len(frames), "ms")
    _map(frames, layout.uprights, "map_sim", seeds=seeds, smooth_every=48)  # 12 m of 0.25 m steps: 10 s at 1.2 m/s


def bench_mapping_rendered(size_px: int, step_m: float, seeds: int) -> None:
    rng = np.random.default_rng(20)
    layout = rack_region(aisles=2, bays=8)
    scene = rack_scene(layout, rng)
    camera = default_camera(size_px=size_px)
    mount = default_mount()
    frames: list[Frame] = []
    spent = 0.0
    for pose in drive_aisles(layout, step_m):
        image, _ = render_fisheye(camera, scene, pose, rng)
        start = time.process_time()
        found = detect_pillars(image, camera)
        spent += time.process_time() - start
        frames.append((pose, vehicle_bearings(mount, found.bearings_rad), found.sigmas_rad, None))
    report("map_rendered_frames", len(frames), "count")
    report("map_rendered_uprights_true", len(layout.uprights), "count")
    report("map_rendered_detect_cpu_per_frame", 1000 * spent / len(frames), "ms")
    _map(frames, layout.uprights, "map_rendered", seeds=seeds, smooth_every=max(1, round(12.0 / step_m)))


class Truth(NamedTuple):
    """A hall's upright lines (each (n, 2), in order along), floor bin centres (B, 2) and their ids (or None)."""

    lines: list[FloatArray]
    spacings: list[float]
    bins: FloatArray
    bin_ids: list[str] | None


def truth_of_layout(layout: HallLayout) -> Truth:
    lines = [layout.uprights[layout.row_of == r] for r in range(len(layout.row_n))]
    return Truth(lines, [float(d) for d in layout.row_d], layout.bin_centres, None)


def truth_of_world(world: World) -> Truth:
    """Upright lines of a simulated world: each row's front or back uprights between two cross aisles."""
    lines, spacings = [], []
    for r, row in enumerate(world.rows):
        for tag in ("F", "B"):
            index = [k for k, i in enumerate(world.uprights.ids) if world.uprights.row[k] == r and i.endswith(tag)]
            xy = world.uprights.xy[index]
            u = row.polygon[1] - row.polygon[0]
            xy = xy[np.argsort(xy @ u)]
            steps = np.hypot(*np.diff(xy, axis=0).T)
            pitch = float(np.median(steps))
            for piece in np.split(xy, np.flatnonzero(steps > 1.1 * pitch) + 1):
                lines.append(piece)
                spacings.append(pitch)
    floor = [b for b in world.bins if b.level == 1]
    return Truth(lines, spacings, np.array([b.polygon.mean(axis=0) for b in floor]), [b.id[:-3] for b in floor])


def _rows_exact(rows: list[RackRow], truth: Truth) -> tuple[int, float]:
    """(true lines fitted upright for upright within 10 cm, largest spacing error of those, metres)."""
    starts = cKDTree(np.vstack([np.vstack([r.uprights[0], r.uprights[-1]]) for r in rows]))
    found, worst = 0, 0.0
    for line, d in zip(truth.lines, truth.spacings, strict=True):
        for k in starts.query_ball_point(line[0], 0.3):
            row = rows[k // 2]
            ordered = row.uprights if k % 2 == 0 else row.uprights[::-1]
            if row.n == len(line) and np.all(np.hypot(*(ordered - line).T) <= 0.1):
                found += 1
                worst = max(worst, abs(row.d_m - d))
                break
    return found, worst


def bench_rows(name: str, truth: Truth, uprights: FloatArray, seeds: int) -> None:
    rows_ok, worst_d, found, invented, errors, same_id, cpu, wall = 0, 0.0, 0, 0, [], 0, [], []
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        kept = rng.random(len(uprights)) >= 0.1
        xy = uprights[kept] + rng.normal(0.0, 0.03, (int(kept.sum()), 2))
        landmarks = np.column_stack([xy, np.tile([0.03**2, 0.0, 0.03**2], (len(xy), 1))])
        with threadpool_limits(1):
            start, start_cpu = time.perf_counter(), time.process_time()
            result = fit_layout(landmarks)
            wall.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
        ok, worst = _rows_exact(result.rows, truth)
        rows_ok += ok
        worst_d = max(worst_d, worst)
        centres = np.array([b.centre for b in result.bins]).reshape(-1, 2)
        to_found, nearest = cKDTree(centres).query(truth.bins)
        to_truth, _ = cKDTree(truth.bins).query(centres)
        found += int((to_found <= 0.1).sum())
        invented += int((to_truth > 0.1).sum())
        errors += to_found[to_found <= 0.1].tolist()
        if truth.bin_ids is not None:
            same_id += sum(
                result.bins[j].id == truth.bin_ids[i] for i, j in enumerate(nearest) if to_found[i] <= 0.1
            )
    tracemalloc.start()
    fit_layout(landmarks)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    ext = uprights.max(axis=0) - uprights.min(axis=0)
    pairs = hough_pairs(uprights, min_length_m=0.9 * 1.5, max_length_m=2.2 * 4.5)
    report(f"{name}_uprights", len(uprights), "count")
    report(f"{name}_extent_x", float(ext[0]), "m")
    report(f"{name}_extent_y", float(ext[1]), "m")
    report(f"{name}_rows", len(truth.lines), "count")
    report(f"{name}_seeds", seeds, "count")
    report(f"{name}_hough_pairs", len(pairs.i), "count")
    report(f"{name}_rows_exact", 100 * rows_ok / (seeds * len(truth.lines)), "%")
    report(f"{name}_rows_wrong", seeds * len(truth.lines) - rows_ok, "count")
    report(f"{name}_spacing_error_max", 1000 * worst_d, "mm")
    report(f"{name}_bins_found", 100 * found / (seeds * len(truth.bins)), "%")
    report(f"{name}_bins_invented", invented, "count")
    report(f"{name}_bin_centre_error_median", 100 * float(np.median(errors)), "cm")
    report(f"{name}_bin_centre_error_max", 100 * float(np.max(errors)), "cm")
    if truth.bin_ids is not None:
        report(f"{name}_bin_ids_as_simulator", 100 * same_id / max(found, 1), "%")
    report(f"{name}_fit_cpu_median", float(np.median(cpu)), "s")
    report(f"{name}_fit_cpu_max", float(np.max(cpu)), "s")
    report(f"{name}_fit_wall_median", float(np.median(wall)), "s")
    report(f"{name}_fit_peak_memory", peak / 2**20, "MiB")


def two_region_hall() -> World:
    """The 250 m x 72 m hall with a second region at 30 degrees and a 3.6 m bay pitch beside the first."""
    layout = copy.deepcopy(hall_layout())
    layout["name"] = "hall-two-regions"
    layout["blocks"] = [
        {"id": "A", "origin_m": [8.0, 8.0], "aisles": 11, "bays": 50, "aisle_width_m": 3.0, "bay_pitch_m": 2.7,
         "rack_depth_m": 1.1, "levels": 5, "level_pitch_m": 1.6, "fill": 0.75, "cross_aisle_every": 25,
         "cross_aisle_width_m": 3.0, "end_corridor_m": 4.0},
        {"id": "B", "origin_m": [180.0, 12.0], "yaw_rad": math.radians(30), "aisles": 4, "bays": 14,
         "aisle_width_m": 3.0, "bay_pitch_m": 3.6, "rack_depth_m": 1.1, "levels": 4, "level_pitch_m": 1.8,
         "fill": 0.6, "end_corridor_m": 0.0},
    ]
    return world_from_layout(layout)


def bench_live(seeds: int) -> None:
    """Fits every 10 frames while a hall with a cross aisle is surveyed: bins made outside the racks."""
    published = invented = 0
    final = []
    hall = rack_region(aisles=3, bays=10, cross_aisle_every=5, cross_aisle_width_m=3.0)
    sigma = math.radians(0.1)
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        mapper = BearingOnlyMapper()
        poses = drive_aisles(hall, 0.5)
        for k, pose in enumerate(poses, start=1):
            b = simulated_bearings(hall.uprights, pose, rng, sigma_rad=sigma, clutter_rate=0.2, miss_rate=0.2)
            mapper.observe(pose, b, np.full(b.size, sigma))
            if k % 10 and k != len(poses):
                continue
            centres = np.array([x.centre for x in fit_landmark_map(mapper.reliable_landmarks()).bins]).reshape(-1, 2)
            published += len(centres)
            if len(centres):
                invented += int((cKDTree(hall.bin_centres).query(centres)[0] > 0.1).sum())
            if k == len(poses):
                final.append(float(np.mean(cKDTree(centres).query(hall.bin_centres)[0] <= 0.1)))
    report("live_fits_bins_published", published, "count")
    report("live_fits_bins_invented", invented, "count")
    report("live_final_bins_found", 100 * float(np.mean(final)), "%")


def _read_odometry(reader: Any, connections: list[Any]) -> tuple[FloatArray, FloatArray]:
    """Stamps (n,) and base poses (n, 3) in the odometry frame of nav_msgs/Odometry messages."""
    from shared.messages import stamp_ns
    from shared.transforms import yaw_from_quaternion

    rows = []
    for connection, _, raw in reader.messages(connections=connections):
        msg = reader.deserialize(raw, connection.msgtype)
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        rows.append((stamp_ns(msg.header), p.x, p.y,
                     yaw_from_quaternion([q.x, q.y, q.z, q.w])))
    table = np.array(sorted(rows), dtype=np.float64).reshape(-1, 4)
    table[:, 3] = np.unwrap(table[:, 3])
    return table[:, 0], table[:, 1:]


def _survey_frames(bag: Path) -> Iterator[Frame]:
    """The survey's frames: true sensor pose, detections, and the sensor pose in the simulator's drifting odometry."""
    from rosbags.highlevel import AnyReader

    from services.pillar_mapping import camera_from_info, image_bgr
    from services.pillar_mapping.bag import _mount, _pose_at, _read_poses
    from services.pillar_mapping.mount import sensor_pose
    from shared.messages import CAMERA_INFO, ODOMETRY, POSE_STAMPED, TYPESTORE, stamp_ns

    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        conns = reader.connections
        images = [c for c in conns if c.topic.endswith("/fisheye/image_raw")]
        info: Any = next(reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(
            connections=[c for c in conns if c.msgtype == CAMERA_INFO]))
        camera = camera_from_info(info)
        mount = _mount(reader, [c for c in conns if c.topic.endswith("tf_static")], str(info.header.frame_id),
                       images[0].topic.split("/")[1] + "/base_link")
        stamps, table = _read_poses(reader, [c for c in conns if c.msgtype == POSE_STAMPED])
        odom_stamps, odom_table = _read_odometry(reader, [c for c in conns if c.msgtype == ODOMETRY])
        for connection, _, raw in reader.messages(connections=images):
            message: Any = reader.deserialize(raw, connection.msgtype)
            pose = _pose_at(stamps, table, stamp_ns(message.header))
            odometry = _pose_at(odom_stamps, odom_table, stamp_ns(message.header))
            if pose is not None and odometry is not None:
                seen = detect_pillars(image_bgr(message), camera)
                x, y, yaw = sensor_pose(mount, pose)
                ox, oy, oyaw = sensor_pose(mount, odometry)
                yield ((float(x), float(y), float(yaw)), vehicle_bearings(mount, seen.bearings_rad), seen.sigmas_rad,
                       (float(ox), float(oy), float(oyaw)))


def bench_sim_survey(seeds: int) -> None:
    """The simulator's demo survey: photo-textured 185 deg fisheye frames at 2 Hz, one pass along each aisle."""
    from services.simulator import sim_run

    world = load_world("demo")
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bag"
        sim_run(world, bag, robots=1, cameras=["fisheye"], fisheye_rate_hz=2.0)
        frames = list(_survey_frames(bag))
    report("survey_frames", len(frames), "count")
    report("survey_uprights_true", len(world.uprights.xy), "count")
    _map(frames, world.uprights.xy, "survey", seeds=seeds, smooth_every=20)


class DemoFrame(NamedTuple):
    """A fisheye frame of the live demo: round, true / tf (map) / odom base poses, camera mount, bearings, stds."""

    round: int
    truth: FloatArray
    tf: FloatArray
    odom: FloatArray
    mount: Any
    bearings: FloatArray
    sigmas: FloatArray


def demo_round_frames(rounds: int) -> tuple[World, list[DemoFrame]]:
    """The live demo (``aisle run --demo``) driven offline: the same world, loop and per-round seeds, each
    frame posed as the worker poses it (tf ``map -> base_link`` at the image stamp) and by the truth."""
    from services.pillar_mapping import camera_from_info, image_bgr
    from services.pillar_mapping.mount import mount_from_transform
    from services.simulator import demo_layout, fisheye_sensor
    from services.simulator.lidar import LidarModel
    from services.simulator.route import survey_route, waypoint_route
    from services.simulator.stream import RobotSpec, simulate
    from shared.transforms import TransformBuffer, add_tf_message, sensor_pose_2d, yaw_from_quaternion

    layout = demo_layout()
    layout["seed"] = 0
    world = world_from_layout(layout)
    survey = survey_route(world)
    loop = np.vstack([survey, waypoint_route(world, [survey[-1], survey[0]])[1:]])
    frames: list[DemoFrame] = []
    start_ns = 1_700_000_000_000_000_000
    for r in range(rounds):
        robot = RobotSpec("robot1", loop, seed=r, cameras=(fisheye_sensor(rate_hz=2.0),),
                          lidar=LidarModel(rate_hz=0.05))  # scans are not used here
        buffer = TransformBuffer(cache_s=10.0)
        truth: dict[int, tuple[float, float, float]] = {}
        image: Any = None
        for output in simulate(world, [robot], start_ns=start_ns):
            message: Any = output.message
            if output.topic in ("tf", "tf_static"):
                add_tf_message(buffer, message, static=output.topic == "tf_static")
            elif output.topic == "ground_truth/pose":
                q = message.pose.orientation
                truth[output.stamp_ns] = (message.pose.position.x, message.pose.position.y,
                                          yaw_from_quaternion([q.x, q.y, q.z, q.w]))
            elif output.topic == "fisheye/image_raw":
                image = message
            elif output.topic == "fisheye/camera_info":
                seen = detect_pillars(image_bgr(image), camera_from_info(message))
                mount = mount_from_transform(buffer.lookup("robot1/base_link", image.header.frame_id, output.stamp_ns))
                frames.append(DemoFrame(
                    r, np.array(truth[output.stamp_ns]),
                    np.array(sensor_pose_2d(buffer.lookup("map", "robot1/base_link", output.stamp_ns))),
                    np.array(sensor_pose_2d(buffer.lookup("robot1/odom", "robot1/base_link", output.stamp_ns))),
                    mount, vehicle_bearings(mount, seen.bearings_rad), seen.sigmas_rad))
            start_ns = max(start_ns, output.stamp_ns)
        start_ns += 1_000_000_000
    return world, frames


def bench_demo_rounds(rounds: int) -> None:
    """Cells of the live demo's floor found at the end of each round, the map fitted every 20 frames (10 s)
    as the worker does: poses from tf as the worker has them (the simulator's localisation error, 1 cm and
    0.002 rad, white) taken as exact, or with that error stated and the map smoothed, or the true poses."""
    from services.pillar_mapping.mount import sensor_pose

    world, frames = demo_round_frames(rounds)
    true_cells = np.array([b.polygon.mean(axis=0) for b in world.bins if b.level == 1])
    stated = np.diag([0.01**2, 0.01**2, 0.002**2])
    cases = {"tf": ("tf", None), "tf_smoothed": ("tf", stated), "truth": ("truth", None)}
    report("demo_cells_true", len(true_cells), "count")
    for case, (which, cov) in cases.items():
        mapper = BearingOnlyMapper()
        fewest = len(true_cells)
        for k, f in enumerate(frames, start=1):
            base = f.truth if which == "truth" else f.tf
            mapper.observe(tuple(sensor_pose(f.mount, base)), f.bearings, f.sigmas, pose_cov=cov,
                           odometry_pose=tuple(sensor_pose(f.mount, f.odom)))
            last = k == len(frames) or frames[k].round != f.round
            if k % 20 and not last:
                continue
            if cov is not None:
                mapper.smooth()
            reliable = mapper.reliable_landmarks()
            centres = np.array([b.centre for b in fit_landmark_map(reliable).bins]).reshape(-1, 2)
            found = int((cKDTree(centres).query(true_cells)[0] <= 0.1).sum()) if len(centres) else 0
            if f.round > 0 or last:  # from the end of the first round on
                fewest = min(fewest, found)
            if last:
                invented = int((cKDTree(true_cells).query(centres)[0] > 0.1).sum()) if len(centres) else 0
                report(f"demo_{case}_round{f.round + 1}_cells_found", found, "count")
                report(f"demo_{case}_round{f.round + 1}_cells_invented", invented, "count")
                report(f"demo_{case}_round{f.round + 1}_rmse", 100 * map_rmse(reliable.means, world.uprights.xy)[0],
                       "cm")
        report(f"demo_{case}_fewest_cells_after_round1", fewest, "count")


def _child_run(args: list[str]) -> tuple[float, float]:
    """(wall, CPU of the child) seconds of ``python -m services.cli ARGS`` in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "services.cli", *args], check=True, capture_output=True,
                   env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def bench_racks_cli(runs: int) -> None:
    """``aisle racks fit`` on a 4,680-upright hall turned 7 degrees (13 aisles of 89 bays, 3 cm noise) and
    ``aisle --help``, each in a fresh process as a user runs them; medians of ``runs``."""
    hall = rack_region(aisles=13, bays=89, theta_rad=math.radians(7.0))
    rng = np.random.default_rng(0)
    xy = hall.uprights + rng.normal(0.0, 0.03, hall.uprights.shape)
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "hall.csv"
        write_landmarks_csv(csv, xy, np.tile(np.eye(2) * 0.03**2, (len(xy), 1, 1)))
        fits = [_child_run(["racks", "fit", str(csv), "--out", str(Path(tmp) / "out")]) for _ in range(runs)]
        helps = [_child_run(["--help"]) for _ in range(runs)]
    report("racks_cli_uprights", len(xy), "count")
    report("racks_cli_fit_wall_median", float(np.median([w for w, _ in fits])), "s")
    report("racks_cli_fit_cpu_median", float(np.median([c for _, c in fits])), "s")
    report("racks_cli_help_wall_median", float(np.median([w for w, _ in helps])), "s")
    report("racks_cli_help_cpu_median", float(np.median([c for _, c in helps])), "s")
    report("racks_cli_load_1min", os.getloadavg()[0], "procs")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer frames and seeds")
    parser.add_argument("--rows-only", action="store_true", help="only the row and bin fitting")
    parser.add_argument("--mapping-only", action="store_true", help="only the mapping (and the options below)")
    parser.add_argument("--seeds", type=int, default=None, help="landmark draws per hall (default 5, quick 2)")
    parser.add_argument("--sim-survey", action="store_true", help="also map the simulator's demo fisheye survey")
    parser.add_argument("--demo-rounds", type=int, default=0,
                        help="also drive this many rounds of the live demo offline and count its cells per round")
    parser.add_argument("--cli-only", action="store_true", help="only `aisle racks fit` and `aisle --help` as run")
    args = parser.parse_args()
    if args.cli_only:
        bench_racks_cli(3 if args.quick else 5)
        return
    frames = 8 if args.quick else 30
    seeds = args.seeds or (2 if args.quick else 5)
    if not args.rows_only:
        p95 = math.radians(0.1)
        if not args.mapping_only:
            p95 = bench_detection(frames, 640)
            bench_detection(frames, 480)
        bench_mapping_simulated(max(p95, math.radians(0.1)), seeds)
        bench_mapping_rendered(480, 0.5 if args.quick else 0.25, seeds)
        bench_live(2 if args.quick else 4)
        if args.sim_survey:
            bench_sim_survey(seeds)
        if args.demo_rounds:
            bench_demo_rounds(args.demo_rounds)
    if args.mapping_only:
        return
    halls: dict[str, Callable[[], tuple[Truth, FloatArray]]] = {
        "hall_250x72": lambda: (truth_of_world(w := load_world("hall")), w.uprights.xy),
        "hall_two_regions": lambda: (truth_of_world(w := two_region_hall()), w.uprights.xy),
        "synthetic_two_regions": lambda: (truth_of_layout(lay := _synthetic_two_regions()), lay.uprights),
    }
    for name, build in halls.items():
        truth, uprights = build()
        bench_rows(name, truth, uprights, seeds)


def _synthetic_two_regions() -> HallLayout:
    """The earlier bench hall: 19 aisles of 26 bays and a 30 degree region of 3.6 m bays (187 m x 108 m)."""
    return merge_layouts(
        rack_region(aisles=19, bays=26),
        rack_region(origin_xy_m=(150.0, 0.0), theta_rad=np.deg2rad(30), aisles=5, bays=12, bay_pitch_m=3.6),
    )


if __name__ == "__main__":
    main()
