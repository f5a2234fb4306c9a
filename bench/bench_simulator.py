"""Simulator speed on the 250 m x 72 m hall (3696 uprights): frames per second of each sensor stream,
and the wall time of the whole hall's lidar survey bag. Also the occupancy agreement figure on the demo.

Prints ``name value unit`` lines. ``--full`` also writes the complete hall survey (scan, odom, TF,
true pose; about 45 minutes of robot time) to a temporary MCAP bag and times it.
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import time
from pathlib import Path

from threadpoolctl import threadpool_limits

from services.occupancy_mapping import build_map
from services.simulator import (
    FisheyeModel,
    LidarModel,
    RgbdModel,
    RobotSpec,
    Segments,
    cast_rays,
    demo_layout,
    drive,
    hall_layout,
    photo_textures,
    render_boxes,
    render_fisheye,
    sim_run,
    simulate,
    surface_agreement,
    survey_route,
    world_from_layout,
    write_bag,
)
from services.simulator.cameras import FISHEYE_MOUNT, RGBD_MOUNT
from services.simulator.stream import _planar_matrix

FRAMES = 20


def _rate(name: str, frames: int, seconds: float) -> None:
    print(f"{name} {frames / seconds:.2f} frames/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--full", action="store_true", help="also time the whole hall survey bag")
    args = parser.parse_args()
    started = time.perf_counter()
    world = world_from_layout(hall_layout())
    print(f"hall_world_build {time.perf_counter() - started:.3f} s")
    print(f"hall_uprights {len(world.uprights.ids)} count")
    started = time.perf_counter()
    route = survey_route(world)
    trajectory = drive(route, speed_mps=1.5)
    print(f"hall_route_plan {time.perf_counter() - started:.3f} s")
    print(f"hall_survey_duration {trajectory.t_s[-1]:.0f} s")
    poses = trajectory.pose[:: max(1, len(trajectory.pose) // FRAMES)][:FRAMES]
    lidar = LidarModel()
    segments = Segments.from_boxes(world.boxes, height_m=lidar.height_m)
    started = time.perf_counter()
    for pose in poses:
        cast_rays(pose[:2], pose[2] + lidar.angle_min_rad, lidar.angle_increment_rad, lidar.beams,
                  [(segments, None)], max_range_m=lidar.range_max_m)
    _rate("lidar_scan", len(poses), time.perf_counter() - started)
    textures = photo_textures()
    model = FisheyeModel()
    started = time.perf_counter()
    for pose in poses[:5]:
        render_fisheye(world.boxes, _planar_matrix(pose) @ FISHEYE_MOUNT, model, textures=textures)
    _rate("fisheye_480", 5, time.perf_counter() - started)
    camera = RgbdModel().camera()
    started = time.perf_counter()
    for pose in poses[:5]:
        render_boxes(world.boxes, _planar_matrix(pose) @ RGBD_MOUNT, camera, textures=textures)
    _rate("rgbd_640x480", 5, time.perf_counter() - started)
    robot = RobotSpec("robot1", route, speed_mps=1.5)
    with tempfile.TemporaryDirectory() as tmp:
        started = time.perf_counter()
        outputs = itertools.takewhile(lambda o: o.stamp_ns < 1_700_000_000_000_000_000 + 120 * 10**9,
                                      simulate(world, [robot], trajectories={"robot1": trajectory}))
        write_bag(outputs, Path(tmp) / "part")
        elapsed = time.perf_counter() - started
        print(f"hall_survey_bag_speed {120.0 / elapsed:.1f} x_realtime")
        print(f"hall_survey_bag_estimate {trajectory.t_s[-1] * elapsed / 120.0 / 60.0:.1f} min")
        if args.full:
            started = time.perf_counter()
            write_bag(simulate(world, [robot], trajectories={"robot1": trajectory}), Path(tmp) / "full")
            print(f"hall_survey_bag_full {(time.perf_counter() - started) / 60.0:.1f} min")
        demo = world_from_layout(demo_layout())
        sim_run(demo, Path(tmp) / "demo", speed_mps=1.5)
        grid = build_map(Path(tmp) / "demo", resolution_m=0.05)
        agreement = surface_agreement(grid.to_layer("occupancy"), demo, tolerance_m=0.1)
    print(f"demo_surface_recall {agreement.surface_recall:.3f} fraction")
    print(f"demo_surface_recall_observed {agreement.surface_recall_observed:.3f} fraction")
    print(f"demo_occupied_precision {agreement.occupied_precision:.3f} fraction")


if __name__ == "__main__":
    with threadpool_limits(1):
        main()
