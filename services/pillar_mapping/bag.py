"""Detection and bearing-only mapping over a recorded rosbag2."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import NamedTuple, cast

import numpy as np
import numpy.typing as npt
from rosbags.highlevel import AnyReader
from rosbags.highlevel.anyreader import AnyReaderError
from rosbags.interfaces import Connection
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseStamped as PoseStamped
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from rosbags.typesys.stores.ros2_jazzy import tf2_msgs__msg__TFMessage as TFMessage

from services.pillar_mapping.camera import FisheyeCamera, camera_from_info
from services.pillar_mapping.detection import detect_pillars
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.landmark_io import write_landmarks_csv
from services.pillar_mapping.mapper import BearingOnlyMapper, LandmarkMap
from services.pillar_mapping.mount import (
    CameraMount,
    default_mount,
    mount_from_transform,
    sensor_pose,
    vehicle_bearings,
)
from shared import messages
from shared.messages import CAMERA_INFO, IMAGE, POSE_STAMPED, TF_MESSAGE, TYPESTORE
from shared.transforms import TransformBuffer, add_tf_message, yaw_from_quaternion

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

IMAGE_SUFFIX = "/fisheye/image_raw"
INFO_SUFFIX = "/fisheye/camera_info"
POSE_SUFFIX = "/ground_truth/pose"


class PillarMapResult(NamedTuple):
    """A landmark map built from a bag, with counts of the frames used and skipped."""

    landmarks: LandmarkMap
    frames_used: int
    frames_skipped: int


def image_bgr(message: Image) -> npt.NDArray[np.uint8]:
    """The BGR pixels of a sensor_msgs/Image in ``bgr8``, ``rgb8``, ``bgra8``, ``rgba8`` or ``mono8``."""
    channels = {"bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4, "mono8": 1}.get(message.encoding)
    if channels is None:
        raise PillarMappingError(f"image encoding {message.encoding!r} is not supported")
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.asarray(message.data, dtype=np.uint8)
    if data.size < height * step or step < width * channels:
        raise PillarMappingError(f"image of {data.size} bytes is too short for {width}x{height}, step {step}")
    pixels = data[: height * step].reshape(height, step)[:, : width * channels].reshape(height, width, channels)
    if channels == 1:
        return np.repeat(pixels, 3, axis=2)
    if message.encoding.startswith("rgb"):
        return np.ascontiguousarray(pixels[..., 2::-1])
    return np.ascontiguousarray(pixels[..., :3])


def _namespace(topic: str, suffix: str) -> str | None:
    return topic[: -len(suffix)] if topic.endswith(suffix) else None


def _read_poses(reader: AnyReader, connections: list[Connection]) -> tuple[FloatArray, FloatArray]:
    stamps, poses = [], []
    for connection, _, raw in reader.messages(connections=connections):
        msg = cast(PoseStamped, reader.deserialize(raw, connection.msgtype))
        q = msg.pose.orientation
        stamps.append(messages.stamp_ns(msg.header))
        poses.append([msg.pose.position.x, msg.pose.position.y, yaw_from_quaternion([q.x, q.y, q.z, q.w])])
    order = np.argsort(stamps)
    table = np.asarray(poses, dtype=np.float64).reshape(-1, 3)[order]
    table[:, 2] = np.unwrap(table[:, 2])
    return np.asarray(stamps, dtype=np.float64)[order], table


def _pose_at(stamps: FloatArray, poses: FloatArray, stamp_ns: int) -> FloatArray | None:
    if stamps.size == 0 or not stamps[0] <= stamp_ns <= stamps[-1]:
        return None
    return np.array([np.interp(stamp_ns, stamps, poses[:, i]) for i in range(3)])


def _mount(reader: AnyReader, connections: list[Connection], camera_frame: str, base_frame: str) -> CameraMount:
    buffer = TransformBuffer()
    for connection, _, raw in reader.messages(connections=connections) if connections else ():
        add_tf_message(buffer, cast(TFMessage, reader.deserialize(raw, connection.msgtype)), static=True)
    if camera_frame and buffer.can_transform(base_frame, camera_frame, None):
        return mount_from_transform(buffer.lookup(base_frame, camera_frame, None))
    logger.info("no static transform %s -> %s; assuming the default downward mount", camera_frame, base_frame)
    return default_mount()


def map_pillars_from_bag(
    bag_path: Path,
    out_dir: Path | None = None,
    *,
    namespace: str | None = None,
    base_frame: str = "base_link",
    mapper: BearingOnlyMapper | None = None,
) -> PillarMapResult:
    """Detect uprights in every fisheye frame of a bag and map them with the localisation pose.

    Reads ``/<ns>/fisheye/image_raw`` (sensor_msgs/Image), ``/<ns>/fisheye/camera_info``
    (equidistant CameraInfo) and ``/<ns>/ground_truth/pose`` (geometry_msgs/PoseStamped of
    ``base_frame``, interpolated to each image stamp); the camera mount comes from
    ``/tf_static`` when it links the camera frame to ``base_frame``, else
    :func:`~services.pillar_mapping.mount.default_mount`. With ``out_dir``, writes
    ``out_dir/pillars.csv`` (``x,y,sxx,sxy,syy``).

    Raises
    ------
    PillarMappingError
        If the bag cannot be read or lacks the image, camera info or pose topics.
    """
    bag_path = Path(bag_path)
    if not bag_path.exists():
        raise PillarMappingError(f"bag {bag_path} does not exist")
    mapper = mapper or BearingOnlyMapper()
    used = skipped = 0
    try:
        with AnyReader([bag_path], default_typestore=TYPESTORE) as reader:
            conns = reader.connections
            images = [c for c in conns if c.msgtype == IMAGE and _namespace(c.topic, IMAGE_SUFFIX) is not None]
            if namespace is None and images:
                namespace = _namespace(images[0].topic, IMAGE_SUFFIX)
            images = [c for c in images if c.topic == f"{namespace}{IMAGE_SUFFIX}"]
            infos = [c for c in conns if c.msgtype == CAMERA_INFO and c.topic == f"{namespace}{INFO_SUFFIX}"]
            poses = [c for c in conns if c.msgtype == POSE_STAMPED and c.topic == f"{namespace}{POSE_SUFFIX}"]
            for what, found in (("image", images), ("camera info", infos), ("pose", poses)):
                if not found:
                    raise PillarMappingError(f"bag {bag_path} has no {what} topic under namespace {namespace!r}")
            info_msg = cast(CameraInfo, next(reader.deserialize(raw, c.msgtype)
                                             for c, _, raw in reader.messages(connections=infos)))
            camera: FisheyeCamera = camera_from_info(info_msg)
            tf_static = [c for c in conns if c.msgtype == TF_MESSAGE and c.topic.endswith("tf_static")]
            mount = _mount(reader, tf_static, str(info_msg.header.frame_id), base_frame)
            stamps, table = _read_poses(reader, poses)
            for connection, _, raw in reader.messages(connections=images):
                msg = cast(Image, reader.deserialize(raw, connection.msgtype))
                pose = _pose_at(stamps, table, messages.stamp_ns(msg.header))
                if pose is None:
                    skipped += 1
                    continue
                try:
                    seen = detect_pillars(image_bgr(msg), camera)
                except PillarMappingError as err:
                    skipped += 1
                    logger.warning("frame at %d ns skipped: %s", messages.stamp_ns(msg.header), err)
                    continue
                mapper.observe(
                    tuple(sensor_pose(mount, pose)), vehicle_bearings(mount, seen.bearings_rad), seen.sigmas_rad
                )
                used += 1
    except (AnyReaderError, OSError) as err:
        raise PillarMappingError(f"cannot read bag {bag_path}: {err}") from err
    landmarks = mapper.reliable_landmarks()
    logger.info("mapped %d uprights from %d frames of %s (%d skipped)", len(landmarks.means), used, bag_path, skipped)
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        write_landmarks_csv(Path(out_dir) / "pillars.csv", landmarks.means, landmarks.covs)
    return PillarMapResult(landmarks, used, skipped)
