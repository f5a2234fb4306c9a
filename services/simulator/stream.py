"""The simulation loop: robots drive their routes and their sensors emit time-ordered ROS messages.

One :class:`Robot` yields odometry, TF (``map -> odom`` from a localisation-like correction, ``odom ->
base_link`` from drifting odometry, static sensor mountings), the true pose and laser scans, plus
camera frames when camera models are given. Frames of a robot in namespace ``ns`` are prefixed
``ns/`` (tf_prefix style: ``ns/odom``, ``ns/base_link``), the map frame is the shared ``map``, so
several robots fit in one TF tree and one bag.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from services.simulator import rosmsgs
from services.simulator.actors import dynamic_boxes
from services.simulator.errors import SimulatorError
from services.simulator.lidar import LidarModel, Segments, add_noise, cast_rays
from services.simulator.motion import Trajectory, drifting_odometry, drive, localisation_correction
from services.simulator.world import FloatArray, ObjectClass, World
from shared.transforms import from_matrix

MAP_FRAME = "map"
STATIC_PERIOD_S = 2.0
"""How often the static transforms are re-sent (late subscribers of a live bus need them)."""

_INTENSITY = np.full(len(ObjectClass) + 1, 60.0)
"""Laser intensity by object class; the last entry (index -1) is for beams without a return."""
_INTENSITY[[ObjectClass.UPRIGHT, ObjectClass.GATE, -1]] = (200.0, 120.0, 0.0)


class Output(NamedTuple):
    """One message: stamp (ns), robot namespace, topic under it, message type and message."""

    stamp_ns: int
    namespace: str
    topic: str
    msgtype: str
    message: Any


class CameraSensor(NamedTuple):
    """A camera to run: its rate, mounting (4x4 base_link -> optical frame) and a frame maker.

    ``render(world, time_s, optical_in_map_4x4)`` returns ``[(topic, image array or camera info
    keyword), ...]``; see :func:`services.simulator.cameras.fisheye_sensor`.
    """

    name: str
    rate_hz: float
    mount: FloatArray
    frame: str
    render: Callable[[World, float, FloatArray, int, str], list[tuple[str, str, Any]]]


@dataclass(frozen=True)
class RobotSpec:
    """A simulated robot: namespace, route waypoints (k, 2), speed, random seed, optional start delay."""

    namespace: str
    route: FloatArray
    speed_mps: float = 1.2
    seed: int = 0
    start_delay_s: float = 0.0
    odom_rate_hz: float = 20.0
    lidar: LidarModel = field(default_factory=LidarModel)
    cameras: tuple[CameraSensor, ...] = ()


def _frame(namespace: str, name: str) -> str:
    return f"{namespace}/{name}" if namespace else name


def _planar_matrix(pose: npt.NDArray[np.float64], z: float = 0.0) -> FloatArray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = (pose[0], pose[1], z)
    return m


class _Robot:
    """Messages of one robot in time order."""

    def __init__(self, world: World, spec: RobotSpec, *, start_ns: int, static_segments: Segments,
                 trajectory: Trajectory | None = None) -> None:
        if spec.odom_rate_hz <= 0 or spec.odom_rate_hz < spec.lidar.rate_hz:
            raise SimulatorError(f"robot {spec.namespace!r}: odom rate {spec.odom_rate_hz} Hz must be >= the lidar's")
        self.world, self.spec = world, spec
        self.start_ns = start_ns + round(spec.start_delay_s * 1e9)
        self.static_segments = static_segments
        self.rng = np.random.default_rng(spec.seed)
        self.trajectory = trajectory or drive(spec.route, rate_hz=spec.odom_rate_hz, speed_mps=spec.speed_mps)
        self.odom = drifting_odometry(self.trajectory, self.rng)
        self.map_to_odom = localisation_correction(self.trajectory.pose, self.odom, self.rng)
        ns = spec.namespace
        self.frames = {name: _frame(ns, name) for name in ("odom", "base_link", "laser")}

    def _static(self, stamp_ns: int) -> Output:
        lidar = self.spec.lidar
        transforms = [rosmsgs.transform_stamped(stamp_ns, self.frames["base_link"], self.frames["laser"],
                                                (*lidar.mount_xy_m, lidar.height_m), np.array([0.0, 0.0, 0.0, 1.0]))]
        for camera in self.spec.cameras:
            mount = from_matrix(camera.mount)
            transforms.append(rosmsgs.transform_stamped(stamp_ns, self.frames["base_link"],
                                                        _frame(self.spec.namespace, camera.frame),
                                                        tuple(mount.translation), mount.rotation))
        return Output(stamp_ns, self.spec.namespace, "tf_static", *rosmsgs.tf_message(transforms))

    def _scan(self, stamp_ns: int, time_s: float, pose: npt.NDArray[np.float64]) -> Output:
        lidar = self.spec.lidar
        c, s = math.cos(pose[2]), math.sin(pose[2])
        origin = pose[:2] + np.array([c * lidar.mount_xy_m[0] - s * lidar.mount_xy_m[1],
                                      s * lidar.mount_xy_m[0] + c * lidar.mount_xy_m[1]])
        dynamic = Segments.from_boxes(dynamic_boxes(self.world, time_s), height_m=lidar.height_m)
        ranges, labels = cast_rays(origin, pose[2] + lidar.angle_min_rad, lidar.angle_increment_rad, lidar.beams,
                                   [(self.static_segments, None), (dynamic, None)], max_range_m=lidar.range_max_m)
        noisy = add_noise(ranges, lidar, self.rng)
        intensities = np.where(np.isfinite(noisy), _INTENSITY[labels], 0.0)
        return Output(stamp_ns, self.spec.namespace, "scan", *rosmsgs.laser_scan(
            stamp_ns, self.frames["laser"], angle_min_rad=lidar.angle_min_rad,
            angle_increment_rad=lidar.angle_increment_rad, scan_time_s=1.0 / lidar.rate_hz,
            range_min_m=lidar.range_min_m, range_max_m=lidar.range_max_m, ranges=noisy, intensities=intensities))

    def messages(self) -> Iterator[Output]:
        spec, traj, ns, frames = self.spec, self.trajectory, self.spec.namespace, self.frames
        dt = 1.0 / spec.odom_rate_hz
        scan_every = max(1, round(spec.odom_rate_hz / spec.lidar.rate_hz))
        camera_every = [max(1, round(spec.odom_rate_hz / camera.rate_hz)) for camera in spec.cameras]
        static_every = max(1, round(STATIC_PERIOD_S / dt))
        for i, time_s in enumerate(traj.t_s):
            stamp_ns = self.start_ns + round(float(time_s) * 1e9)
            world_time_s = float(time_s) + spec.start_delay_s
            pose = traj.pose[i]
            if i % static_every == 0:
                yield self._static(stamp_ns)
            yield Output(stamp_ns, ns, "odom", *rosmsgs.odometry(
                stamp_ns, frames["odom"], frames["base_link"], self.odom[i], traj.twist[i],
                position_var_m2=(0.01 + 0.002 * float(time_s)) ** 2, yaw_var_rad2=(0.005 + 1e-4 * float(time_s)) ** 2))
            yield Output(stamp_ns, ns, "tf", *rosmsgs.tf_message([
                rosmsgs.planar_transform(stamp_ns, MAP_FRAME, frames["odom"], self.map_to_odom[i]),
                rosmsgs.planar_transform(stamp_ns, frames["odom"], frames["base_link"], self.odom[i])]))
            yield Output(stamp_ns, ns, "ground_truth/pose", *rosmsgs.pose_stamped(stamp_ns, MAP_FRAME, pose))
            if i % scan_every == 0:
                yield self._scan(stamp_ns, world_time_s, pose)
            for camera, every in zip(spec.cameras, camera_every, strict=True):
                if i % every == 0:
                    optical = _planar_matrix(pose) @ camera.mount
                    frame = _frame(ns, camera.frame)
                    for topic, msgtype, message in camera.render(self.world, world_time_s, optical, stamp_ns, frame):
                        yield Output(stamp_ns, ns, topic, msgtype, message)


def simulate(world: World, robots: Iterable[RobotSpec], *, start_ns: int = 1_700_000_000_000_000_000,
             trajectories: dict[str, Trajectory] | None = None) -> Iterator[Output]:
    """Every message of every robot, merged in stamp order.

    Parameters
    ----------
    world : World
        The world the robots drive in.
    robots : iterable of RobotSpec
        The robots; namespaces must differ.
    start_ns : int
        Stamp of the first tick, nanoseconds (live runs pass the wall clock).
    trajectories : dict, optional
        Precomputed trajectories by namespace (otherwise driven from each robot's route).
    """
    specs = list(robots)
    names = [spec.namespace for spec in specs]
    if not specs or len(set(names)) != len(names):
        raise SimulatorError(f"need at least one robot with distinct namespaces, got {names}")
    heights = {spec.lidar.height_m for spec in specs}
    static = {h: Segments.from_boxes(world.boxes, height_m=h) for h in heights}
    streams = [_Robot(world, spec, start_ns=start_ns, static_segments=static[spec.lidar.height_m],
                      trajectory=(trajectories or {}).get(spec.namespace)).messages() for spec in specs]
    yield from heapq.merge(*streams, key=lambda output: output.stamp_ns)


def robot_trajectory(spec: RobotSpec) -> Trajectory:
    """The true trajectory ``spec`` drives (the same :func:`simulate` uses)."""
    return drive(spec.route, rate_hz=spec.odom_rate_hz, speed_mps=spec.speed_mps)


def topic_name(output: Output) -> str:
    """``/<namespace>/<topic>`` of an output (``/<topic>`` without a namespace)."""
    return "/" + "/".join(part for part in (output.namespace, output.topic) if part)
