"""Warehouse simulator: worlds from layouts, exact ground truth, and ROS 2 sensor traffic (lidar,
odometry, TF, fisheye and RGB-D cameras) for one or more robots, into a rosbag2 or onto the bus."""

from services.simulator.agreement import SurfaceAgreement, surface_agreement
from services.simulator.bag import write_bag
from services.simulator.cameras import (
    FisheyeModel,
    RgbdModel,
    depth_image_mm,
    fisheye_sensor,
    photo_textures,
    rack_rgbd_mount,
    render_fisheye,
    rgbd_sensor,
)
from services.simulator.commands import load_world, robot_specs, sim_live, sim_run, sim_world
from services.simulator.errors import SimulatorError
from services.simulator.files import actor_tracks, read_layout, write_ground_truth
from services.simulator.groundtruth import GroundTruthGrids, ground_truth_features, ground_truth_grids, surface_mask
from services.simulator.layout import world_from_layout
from services.simulator.lidar import LidarModel, Segments, cast_rays
from services.simulator.live import publish_live, run_demo
from services.simulator.loads import LoadOptions, loaded_layout, rack_view
from services.simulator.motion import Trajectory, drifting_odometry, drive
from services.simulator.presets import demo_layout, hall_layout, random_layout
from services.simulator.render import PinholeCamera, Rendered, render_boxes
from services.simulator.route import survey_route, waypoint_route
from services.simulator.stream import CameraSensor, Output, RobotSpec, simulate
from services.simulator.world import LoadTruth, ObjectClass, World

__all__ = [
    "CameraSensor",
    "FisheyeModel",
    "GroundTruthGrids",
    "LidarModel",
    "LoadOptions",
    "LoadTruth",
    "ObjectClass",
    "Output",
    "PinholeCamera",
    "Rendered",
    "RgbdModel",
    "RobotSpec",
    "Segments",
    "SimulatorError",
    "SurfaceAgreement",
    "Trajectory",
    "World",
    "actor_tracks",
    "cast_rays",
    "demo_layout",
    "depth_image_mm",
    "drifting_odometry",
    "drive",
    "fisheye_sensor",
    "ground_truth_features",
    "ground_truth_grids",
    "hall_layout",
    "load_world",
    "loaded_layout",
    "photo_textures",
    "publish_live",
    "rack_rgbd_mount",
    "rack_view",
    "random_layout",
    "read_layout",
    "render_boxes",
    "render_fisheye",
    "rgbd_sensor",
    "robot_specs",
    "run_demo",
    "sim_live",
    "sim_run",
    "sim_world",
    "simulate",
    "surface_agreement",
    "surface_mask",
    "survey_route",
    "waypoint_route",
    "world_from_layout",
    "write_bag",
    "write_ground_truth",
]
