"""A stand-in ROS 2 robot: publishes a scanned square room exactly as rmw_zenoh would.

Deliberately independent of Aisle's bus code: raw zenoh, keys and the 33-byte attachment
built by hand, CDR from the standard message definitions. Run as a separate process:

    python tests/rmw_zenoh_talker.py --connect tcp/127.0.0.1:7447 --namespace robot1 --scans 40
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import time
from typing import Any

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore

ROOM_HALF_M = 4.0
STORE = get_typestore(Stores.ROS2_JAZZY)


def room_ranges(x: float, y: float, yaw: float, angles: np.ndarray) -> np.ndarray:
    """Distances from (x, y) along bearings ``angles`` (sensor frame) to the walls of a square room."""
    world = yaw + angles
    dx, dy = np.cos(world), np.sin(world)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (ROOM_HALF_M - x) / dx, np.where(dx < 0, (-ROOM_HALF_M - x) / dx, np.inf))
        ty = np.where(dy > 0, (ROOM_HALF_M - y) / dy, np.where(dy < 0, (-ROOM_HALF_M - y) / dy, np.inf))
    return np.minimum(tx, ty)


def key(domain: int, namespace: str, topic: str, msgtype: str) -> str:
    package, kind, name = msgtype.split("/")
    name_part = "/".join(p for p in (namespace, topic) if p)
    return f"{domain}/{name_part}/{package}::{kind}::dds_::{name}_/{STORE.hash_rihs01(msgtype)}"


class Talker:
    def __init__(self, session: zenoh.Session, domain: int, namespace: str) -> None:
        self.session = session
        self.domain = domain
        self.namespace = namespace
        self.publishers: dict[str, tuple[zenoh.Publisher, bytes, list[int]]] = {}

    def declare(self, topic: str, msgtype: str) -> None:
        publisher = self.session.declare_publisher(key(self.domain, self.namespace, topic, msgtype))
        self.publishers[topic] = (publisher, os.urandom(16), [1])

    def wait_for_subscribers(self, timeout_s: float = 15.0) -> None:
        """Block until every declared topic has a matching subscriber (rmw_zenoh does not wait; we must)."""
        deadline = time.monotonic() + timeout_s
        while not all(p.matching_status.matching for p, _, _ in self.publishers.values()):  # type: ignore[attr-defined]
            if time.monotonic() > deadline:
                raise TimeoutError("no subscriber matched within the timeout")
            time.sleep(0.02)

    def publish(self, topic: str, msgtype: str, message: object) -> None:
        publisher, gid, seq = self.publishers[topic]
        attachment = struct.pack("<qqB16s", seq[0], time.time_ns(), 16, gid)
        seq[0] += 1
        publisher.put(bytes(STORE.serialize_cdr(message, msgtype)), attachment=attachment)


def stamp(ns: int) -> Any:
    return STORE.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def header(ns: int, frame: str) -> Any:
    return STORE.types["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame)


def transform(ns: int, parent: str, child: str, x: float, y: float, yaw: float) -> Any:
    t = STORE.types
    return t["geometry_msgs/msg/TransformStamped"](
        header=header(ns, parent), child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))))


def odometry(ns: int, x: float, y: float, yaw: float) -> Any:
    t = STORE.types
    zero = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return t["nav_msgs/msg/Odometry"](
        header=header(ns, "odom"), child_frame_id="base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))),
            covariance=np.zeros(36)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", required=True)
    parser.add_argument("--namespace", default="robot1")
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--scans", type=int, default=40)
    parser.add_argument("--period", type=float, default=0.02)
    args = parser.parse_args()
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    t = STORE.types
    with zenoh.open(config) as session:
        talker = Talker(session, args.domain, args.namespace)
        for topic, msgtype in (("tf_static", "tf2_msgs/msg/TFMessage"), ("odom", "nav_msgs/msg/Odometry"),
                               ("scan", "sensor_msgs/msg/LaserScan")):
            talker.declare(topic, msgtype)
        talker.wait_for_subscribers()
        start = time.time_ns()
        talker.publish("tf_static", "tf2_msgs/msg/TFMessage", t["tf2_msgs/msg/TFMessage"](
            transforms=[transform(start, "base_link", "laser", 0.2, 0.0, 0.0)]))
        angles = np.linspace(-math.pi, math.pi, 720, endpoint=False)
        for i in range(args.scans):
            ns = start + i * 100_000_000
            phase = 2 * math.pi * i / max(args.scans, 1)
            x, y, yaw = 1.5 * math.cos(phase), 1.5 * math.sin(phase), phase
            talker.publish("odom", "nav_msgs/msg/Odometry", odometry(ns, x, y, yaw))
            lx, ly = x + 0.2 * math.cos(yaw), y + 0.2 * math.sin(yaw)
            ranges = room_ranges(lx, ly, yaw, angles).astype(np.float32)
            talker.publish("scan", "sensor_msgs/msg/LaserScan", t["sensor_msgs/msg/LaserScan"](
                header=header(ns, "laser"), angle_min=float(angles[0]), angle_max=float(angles[-1]),
                angle_increment=float(angles[1] - angles[0]), time_increment=0.0, scan_time=0.1, range_min=0.05,
                range_max=20.0, ranges=ranges, intensities=np.zeros(0, np.float32)))
            time.sleep(args.period)
        # one more odometry after the last scan so every scan can be interpolated
        talker.publish("odom", "nav_msgs/msg/Odometry", odometry(start + args.scans * 100_000_000, 1.5, 0.0, 0.0))
        time.sleep(0.5)


if __name__ == "__main__":
    main()
