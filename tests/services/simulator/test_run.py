"""Survey runs: odometry drifts but TF puts the robot on its true pose; bags build maps that match the world."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from services.occupancy_mapping import build_map
from services.simulator import (
    RobotSpec,
    demo_layout,
    drive,
    robot_specs,
    sim_run,
    simulate,
    surface_agreement,
    survey_route,
    world_from_layout,
)
from services.simulator.motion import compose_se2, drifting_odometry, localisation_correction
from shared.messages import TYPESTORE
from shared.transforms import yaw_from_quaternion


def test_drive_reaches_the_last_waypoint_within_speed_limits() -> None:
    waypoints = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]])
    trajectory = drive(waypoints, rate_hz=20.0, speed_mps=1.0)
    assert np.hypot(*(trajectory.pose[-1, :2] - waypoints[-1])) < 0.15
    assert trajectory.twist[:, 0].max() <= 1.0 + 1e-9
    steps = np.hypot(*np.diff(trajectory.pose[:, :2], axis=0).T)
    assert steps.max() <= 1.0 / 20.0 + 1e-9


def test_localisation_correction_puts_drifting_odometry_on_the_true_pose() -> None:
    trajectory = drive(np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 20.0]]), rate_hz=20.0)
    rng = np.random.default_rng(3)
    odom = drifting_odometry(trajectory, rng, gyro_bias_std_rad_s=0.01)
    map_to_odom = localisation_correction(trajectory.pose, odom, rng, position_noise_m=0.0, yaw_noise_rad=0.0)
    np.testing.assert_allclose(compose_se2(map_to_odom, odom), trajectory.pose, atol=1e-9)
    drift = np.hypot(*(compose_se2(map_to_odom[:1].repeat(len(odom), 0), odom)[:, :2] - trajectory.pose[:, :2]).T)
    assert drift[-1] > 0.01


def test_bag_has_every_topic_under_each_robot_and_ground_truth_beside_it(tmp_path: Path) -> None:
    bag = tmp_path / "survey"
    written: Counter[str] = sim_run(world_from_layout(demo_layout()), bag, robots=2,
                                    waypoints=[[2.0, 4.0], [8.0, 4.0]], speed_mps=2.0)
    for ns in ("robot1", "robot2"):
        for topic in ("scan", "odom", "tf", "tf_static", "ground_truth/pose"):
            assert written[f"/{ns}/{topic}"] > 0
    assert (tmp_path / "survey.truth" / "world.geojson").exists()
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        assert {c.topic for c in reader.connections} == set(written)


def test_tf_chain_gives_the_true_pose(tmp_path: Path) -> None:
    world = world_from_layout(demo_layout())
    route = survey_route(world)[:3]
    outputs = list(simulate(world, [RobotSpec("r", route, speed_mps=2.0)]))
    truth = {o.stamp_ns: o.message.pose for o in outputs if o.topic == "ground_truth/pose"}
    for output in outputs:
        if output.topic != "tf":
            continue
        (m2o, o2b) = output.message.transforms
        assert (m2o.header.frame_id, m2o.child_frame_id, o2b.child_frame_id) == ("map", "r/odom", "r/base_link")
        a = np.array([[m2o.transform.translation.x, m2o.transform.translation.y,
                       yaw_from_quaternion([getattr(m2o.transform.rotation, k) for k in "xyzw"])]])
        b = np.array([[o2b.transform.translation.x, o2b.transform.translation.y,
                       yaw_from_quaternion([getattr(o2b.transform.rotation, k) for k in "xyzw"])]])
        pose = compose_se2(a, b)[0]
        true = truth[output.stamp_ns]
        assert math.hypot(pose[0] - true.position.x, pose[1] - true.position.y) < 0.06


@pytest.mark.slow
def test_occupancy_map_from_a_sim_bag_matches_the_true_surfaces(tmp_path: Path) -> None:
    bag = tmp_path / "survey"
    sim_run(world_from_layout(demo_layout()), bag, speed_mps=2.0)
    grid = build_map(bag, resolution_m=0.05)
    agreement = surface_agreement(grid.to_layer("occupancy"), world_from_layout(demo_layout()), tolerance_m=0.1)
    assert agreement.occupied_precision > 0.9
    assert agreement.surface_recall_observed > 0.7


def test_robot_specs_refuse_unknown_cameras() -> None:
    world = world_from_layout(demo_layout())
    with pytest.raises(ValueError, match="unknown cameras"):
        robot_specs(world, cameras=["thermal"])
