"""The one typestore: standard ROS 2 types plus Aisle's own ``aisle_msgs`` definitions.

Payloads on the bus and in rosbag2 files are CDR with the encapsulation header, exactly
as ROS 2 middlewares write them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Final

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

MSG_DIR: Final = Path(__file__).parent / "msg"

LASER_SCAN: Final = "sensor_msgs/msg/LaserScan"
IMAGE: Final = "sensor_msgs/msg/Image"
CAMERA_INFO: Final = "sensor_msgs/msg/CameraInfo"
ODOMETRY: Final = "nav_msgs/msg/Odometry"
OCCUPANCY_GRID: Final = "nav_msgs/msg/OccupancyGrid"
POSE_STAMPED: Final = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE: Final = "tf2_msgs/msg/TFMessage"
MAP_EVENT: Final = "aisle_msgs/msg/MapEvent"
ANNOTATED_SCAN: Final = "aisle_msgs/msg/AnnotatedScan"
PILLAR_BEARINGS: Final = "aisle_msgs/msg/PillarBearings"

STANDARD_TYPES: Final = (LASER_SCAN, IMAGE, CAMERA_INFO, ODOMETRY, OCCUPANCY_GRID, POSE_STAMPED, TF_MESSAGE)
AISLE_TYPES: Final = (MAP_EVENT, ANNOTATED_SCAN, PILLAR_BEARINGS)


class MessageError(ValueError):
    """A payload that is not a valid message of the expected type."""


def _build_typestore() -> Typestore:
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for path in sorted(MSG_DIR.glob("*/msg/*.msg")):
        name = f"{path.parent.parent.name}/msg/{path.stem}"
        types.update(get_types_from_msg(path.read_text(), name))
    store.register(types)
    return store


TYPESTORE: Final = _build_typestore()


def serialize(message: Any, msgtype: str) -> bytes:
    """CDR bytes (with encapsulation header) of ``message``."""
    return bytes(TYPESTORE.serialize_cdr(message, msgtype))


def deserialize(payload: bytes | memoryview, msgtype: str) -> Any:
    """Decode CDR ``payload`` as ``msgtype``; raise :class:`MessageError` on anything malformed."""
    if msgtype not in TYPESTORE.fielddefs:
        raise MessageError(f"unknown message type {msgtype}")
    if len(payload) < 4:
        raise MessageError(f"{msgtype}: payload of {len(payload)} bytes has no CDR header")
    try:
        return TYPESTORE.deserialize_cdr(bytes(payload), msgtype)
    except Exception as err:  # rosbags raises assorted errors on truncated or garbled input
        raise MessageError(f"{msgtype}: malformed CDR payload of {len(payload)} bytes: {err}") from err


def message_class(msgtype: str) -> Any:
    """The rosbags dataclass for ``msgtype``, to build messages with."""
    return TYPESTORE.types[msgtype]


def stamp_ns(header: Header) -> int:
    """A header's stamp as integer nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def time_msg(ns: int) -> Time:
    """``builtin_interfaces/Time`` at ``ns`` nanoseconds."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def header(ns: int, frame_id: str) -> Header:
    """``std_msgs/Header`` stamped ``ns`` nanoseconds in frame ``frame_id``."""
    return Header(stamp=time_msg(ns), frame_id=frame_id)


def type_hash(msgtype: str) -> str:
    """The ROS 2 type hash, ``RIHS01_<sha256 hex>``, as rmw implementations compute it."""
    return str(TYPESTORE.hash_rihs01(msgtype))


def dds_type_name(msgtype: str) -> str:
    """``sensor_msgs/msg/LaserScan`` -> ``sensor_msgs::msg::dds_::LaserScan_`` (rmw_zenoh's spelling)."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """Inverse of :func:`dds_type_name`."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        raise MessageError(f"{dds_name!r} is not a DDS type name")
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
