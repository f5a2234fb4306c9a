"""Where each robot's sensors sit: the camera's floor frame and the lidar in the robot's base frame.

The camera's floor frame (the frame of AnnotatedScan's ``camera_pose``) is fixed in the base frame by the
``camera_*_in_base`` settings. The lidar's mount is the robot's ``tf_static`` transform from ``base_frame``
(``<namespace>/base_frame`` where its tree is prefixed so) to the scan's ``header.frame_id``, looked up when a
range scan is placed; without one, the ``lidar_*_in_base`` settings are used (and the worker counts it as
``range_scans_mount_from_settings``). A change of where a mount comes from is logged once.
"""

from __future__ import annotations

import logging

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose

from services.semantic_fusion import se2
from services.semantic_fusion.errors import SemanticFusionError
from shared.settings import SemanticFusionSettings
from shared.transforms import TransformBuffer, sensor_pose, yaw_from_quaternion

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


class SensorMounts:
    """The camera's floor frame and each robot's lidar frames in the robot's base frame.

    Parameters
    ----------
    camera_in_base : (3,) array_like
        (x, y, yaw) of the camera's floor frame in the base frame, metres and radians.
    lidar_in_base : (3,) array_like
        (x, y, yaw) of the lidar in the base frame for robots whose ``tf_static`` does not have it.
    base_frame : str
        The robot frame the lidar's mount is looked up from.
    """

    def __init__(self, *, camera_in_base: npt.ArrayLike, lidar_in_base: npt.ArrayLike, base_frame: str) -> None:
        self.camera_in_base = np.asarray(camera_in_base, dtype=np.float64).reshape(3)
        self.lidar_in_base = np.asarray(lidar_in_base, dtype=np.float64).reshape(3)
        self.base_frame = base_frame.strip("/")
        self._tf: dict[str, TransformBuffer] = {}
        """Each robot's static transforms, by namespace (kept across a robot's restarts)."""
        self._sources: dict[tuple[str, str], str] = {}
        """Where each (namespace, lidar frame)'s mount came from last ("tf" or "settings"), to log changes."""

    @classmethod
    def from_settings(cls, settings: SemanticFusionSettings) -> SensorMounts:
        """The mounts of the stage's settings section (``camera_*_in_base``, ``lidar_*_in_base``, ``base_frame``)."""
        return cls(camera_in_base=(settings.camera_x_in_base_m, settings.camera_y_in_base_m,
                                   settings.camera_yaw_in_base_rad),
                   lidar_in_base=(settings.lidar_x_in_base_m, settings.lidar_y_in_base_m,
                                  settings.lidar_yaw_in_base_rad),
                   base_frame=settings.base_frame)

    def static_tf(self, namespace: str) -> TransformBuffer:
        """The static transforms of the robot under ``namespace`` (to add its tf_static messages to)."""
        return self._tf.setdefault(namespace, TransformBuffer())

    def camera_pose(self, base: Pose) -> FloatArray:
        """The camera floor frame's (x, y, yaw) in the map from the robot base's pose there.

        Raises
        ------
        SemanticFusionError
            A zero quaternion or a non-finite pose.
        """
        p, q = base.position, base.orientation
        try:
            yaw = yaw_from_quaternion((q.x, q.y, q.z, q.w))
        except ValueError as err:
            raise SemanticFusionError(str(err)) from err
        pose = np.array([p.x, p.y, yaw], dtype=np.float64)
        if not np.all(np.isfinite(pose)):
            raise SemanticFusionError(f"not finite: {pose.tolist()}")
        return se2.compose(pose, self.camera_in_base)

    def lidar_in_camera(self, namespace: str, frame_id: str) -> tuple[FloatArray, float, bool]:
        """The lidar frame ``frame_id`` of robot ``namespace`` in the camera's floor frame; -1.0 if its bearings
        turn clockwise in the base frame (mounted upside down), else 1.0; and whether the mount came from tf
        (else from the settings)."""
        tf = self._tf.get(namespace)
        base = f"{namespace.strip('/')}/{self.base_frame}" if namespace.strip("/") else self.base_frame
        try:
            if tf is None:
                raise LookupError("no tf_static received")
            if base not in tf.frames:
                base = self.base_frame  # a tree with frames not prefixed by the namespace
            transform = tf.lookup(base, frame_id, None)
        except LookupError as err:
            self._log(namespace, frame_id, "settings", self.lidar_in_base, str(err))
            return se2.between(self.camera_in_base, self.lidar_in_base), 1.0, False
        pose, sweep = sensor_pose(transform, np.ones(1))
        mount = np.array(pose, dtype=np.float64)
        self._log(namespace, frame_id, "tf", mount, f"from {base!r}")
        return se2.between(self.camera_in_base, mount), float(sweep[0]), True

    def _log(self, namespace: str, frame_id: str, source: str, mount: FloatArray, detail: str) -> None:
        if self._sources.get((namespace, frame_id)) == source:
            return
        self._sources[namespace, frame_id] = source
        level = logging.INFO if source == "tf" else logging.WARNING
        log.log(level, "robot %r: lidar %r at (%.3f m, %.3f m, %.3f rad) in the base frame from %s (%s)",
                namespace or "/", frame_id, *mount, source, detail)
