"""Rigid transforms and a small tf2-like buffer.

A :class:`Transform` maps points from a child (source) frame into a parent (target) frame:
``p_parent = R(rotation) @ p_child + translation``. Quaternions are ``(x, y, z, w)`` like
geometry_msgs/Quaternion. Stamps are integer nanoseconds, lengths metres, angles radians.

:class:`TransformBuffer` keeps, per child frame, its static transform or a bounded time-stamped
history of its dynamic transform, and answers ``lookup(target, source, stamp_ns)`` by walking the
tree, interpolating each link linearly (translation) and by slerp (rotation).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Odometry as Odometry
from rosbags.typesys.stores.ros2_jazzy import tf2_msgs__msg__TFMessage as TFMessage

from shared import messages

__all__ = [
    "Pose2D",
    "Transform",
    "TransformBuffer",
    "add_odometry",
    "add_tf_message",
    "compose",
    "from_matrix",
    "identity",
    "interpolate",
    "invert",
    "quaternion_from_yaw",
    "sensor_pose",
    "sensor_pose_2d",
    "to_matrix",
    "yaw_from_quaternion",
]

FloatArray = npt.NDArray[np.float64]


class Pose2D(NamedTuple):
    """A planar pose: position in metres, heading in radians (counter-clockwise from +x)."""

    x_m: float
    y_m: float
    yaw_rad: float


class Transform(NamedTuple):
    """A rigid 3-D transform: ``translation`` (3,) in metres and unit quaternion ``rotation`` (4,) xyzw."""

    translation: FloatArray
    rotation: FloatArray


def identity() -> Transform:
    """The identity transform."""
    return Transform(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))


def quaternion_from_yaw(yaw_rad: float) -> FloatArray:
    """Unit quaternion (x, y, z, w) of a rotation by ``yaw_rad`` about +z."""
    half = 0.5 * yaw_rad
    return np.array([0.0, 0.0, math.sin(half), math.cos(half)])


def yaw_from_quaternion(rotation_xyzw: npt.ArrayLike) -> float:
    """Heading in radians, in (-pi, pi], of the rotated +x axis projected onto the xy plane."""
    x, y, z, w = _normalised(np.asarray(rotation_xyzw, dtype=np.float64))
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _normalised(q: FloatArray) -> FloatArray:
    norm = float(np.linalg.norm(q))
    if q.shape != (4,) or not math.isfinite(norm) or norm < 1e-9:
        raise ValueError(f"not a usable quaternion: {q.tolist()}")
    return q / norm


def _quat_multiply(a: FloatArray, b: FloatArray) -> FloatArray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _rotation_matrix(q: FloatArray) -> FloatArray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def to_matrix(transform: Transform) -> FloatArray:
    """The 4x4 homogeneous matrix of ``transform``."""
    out = np.eye(4)
    out[:3, :3] = _rotation_matrix(transform.rotation)
    out[:3, 3] = transform.translation
    return out


def from_matrix(matrix: npt.ArrayLike) -> Transform:
    """The transform of a 4x4 homogeneous matrix with an orthonormal rotation block."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"expected a 4x4 matrix, got shape {m.shape}")
    r = m[:3, :3]
    trace = float(np.trace(r))
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + r[i, i] - r[j, j] - r[k, k], 1e-12))
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
    return Transform(m[:3, 3].copy(), _normalised(np.array(q)))


def compose(a: Transform, b: Transform) -> Transform:
    """``a * b``: apply ``b`` first, then ``a`` (frames: a maps B->A and b maps C->B gives C->A)."""
    rotated = _rotation_matrix(a.rotation) @ b.translation
    return Transform(a.translation + rotated, _normalised(_quat_multiply(a.rotation, b.rotation)))


def invert(transform: Transform) -> Transform:
    """The inverse transform."""
    conj = transform.rotation * np.array([-1.0, -1.0, -1.0, 1.0])
    return Transform(-(_rotation_matrix(conj) @ transform.translation), conj)


def interpolate(a: Transform, b: Transform, fraction: float) -> Transform:
    """Lerp of translation and slerp of rotation; ``fraction`` 0 gives ``a``, 1 gives ``b``."""
    qa, qb = a.rotation, b.rotation
    dot = float(np.dot(qa, qb))
    if dot < 0.0:
        qb, dot = -qb, -dot
    if dot > 0.9995:
        q = qa + fraction * (qb - qa)
    else:
        theta = math.acos(min(dot, 1.0))
        q = (math.sin((1 - fraction) * theta) * qa + math.sin(fraction * theta) * qb) / math.sin(theta)
    return Transform(a.translation + fraction * (b.translation - a.translation), _normalised(q))


def sensor_pose(transform: Transform, angles: npt.NDArray[np.float64]) -> tuple[Pose2D, npt.NDArray[np.float64]]:
    """Planar pose of a planar scanner and its bearings as seen in the fixed frame.

    ``transform`` maps the sensor frame into the fixed frame; ``angles`` (n,) are the scan's bearings in
    radians. A sensor mounted upside down (its +z pointing down) sweeps the other way, so its bearings
    change sign.
    """
    x, y, _, _ = transform.rotation
    z_axis_up = 1.0 - 2.0 * (x * x + y * y)
    return sensor_pose_2d(transform), (-angles if z_axis_up < 0 else angles)


def sensor_pose_2d(transform: Transform) -> Pose2D:
    """Planar pose of a sensor whose transform into the fixed frame is ``transform``.

    Position is the translation's x and y; heading is the direction of the sensor's +x axis
    projected onto the fixed frame's xy plane.
    """
    x, y = float(transform.translation[0]), float(transform.translation[1])
    return Pose2D(x, y, yaw_from_quaternion(transform.rotation))


def _frame(name: str) -> str:
    return name.lstrip("/")


@dataclass
class _History:
    parent: str
    stamps: list[int] = field(default_factory=list)
    transforms: list[Transform] = field(default_factory=list)


class TransformBuffer:
    """Static and time-stamped dynamic transforms between named frames, queryable like tf2.

    Parameters
    ----------
    cache_s : float
        Dynamic samples older than this, relative to the newest sample of the same link, are dropped.
    extrapolation_s : float
        How far before the first or after the last sample of a link a lookup may still be
        answered (with the nearest sample).
    """

    def __init__(self, *, cache_s: float = 30.0, extrapolation_s: float = 0.1) -> None:
        if not (cache_s > 0 and extrapolation_s >= 0):
            raise ValueError(
                f"cache_s must be > 0 and extrapolation_s >= 0, got {cache_s}, {extrapolation_s}"
            )
        self._cache_ns = round(cache_s * 1e9)
        self._tolerance_ns = round(extrapolation_s * 1e9)
        self._static: dict[str, tuple[str, Transform]] = {}
        self._dynamic: dict[str, _History] = {}

    @property
    def frames(self) -> frozenset[str]:
        """Every frame named so far, as parent or child."""
        names = set(self._static) | set(self._dynamic)
        names |= {parent for parent, _ in self._static.values()}
        names |= {history.parent for history in self._dynamic.values()}
        return frozenset(names)

    def parent(self, frame: str) -> str | None:
        """The frame ``frame`` hangs under, or None for a root or unknown frame."""
        frame = _frame(frame)
        if frame in self._static:
            return self._static[frame][0]
        history = self._dynamic.get(frame)
        return None if history is None else history.parent

    def set_transform(
        self,
        parent: str,
        child: str,
        stamp_ns: int,
        translation: npt.ArrayLike,
        rotation_xyzw: npt.ArrayLike,
        *,
        static: bool = False,
    ) -> None:
        """Record ``child``'s pose in ``parent`` at ``stamp_ns``; a new parent replaces the old link."""
        parent, child = _frame(parent), _frame(child)
        if not parent or not child or parent == child:
            raise ValueError(f"invalid frames {parent!r} -> {child!r}")
        t = np.asarray(translation, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(t)):
            raise ValueError(f"non-finite translation for {parent} -> {child}")
        transform = Transform(t, _normalised(np.asarray(rotation_xyzw, dtype=np.float64).reshape(4)))
        if static:
            self._static[child] = (parent, transform)
            self._dynamic.pop(child, None)
            return
        self._static.pop(child, None)
        history = self._dynamic.get(child)
        if history is None or history.parent != parent:
            history = self._dynamic[child] = _History(parent)
        i = bisect.bisect_left(history.stamps, stamp_ns)
        if i < len(history.stamps) and history.stamps[i] == stamp_ns:
            history.transforms[i] = transform
        else:
            history.stamps.insert(i, stamp_ns)
            history.transforms.insert(i, transform)
        cut = bisect.bisect_left(history.stamps, history.stamps[-1] - self._cache_ns)
        if cut:
            del history.stamps[:cut]
            del history.transforms[:cut]

    def _chain(self, frame: str) -> list[str]:
        chain = [frame]
        while True:
            link = self._static.get(chain[-1])
            parent = (
                link[0] if link else (self._dynamic[chain[-1]].parent if chain[-1] in self._dynamic else None)
            )
            if parent is None:
                return chain
            if parent in chain:
                raise LookupError(f"transform loop through {parent!r}")
            chain.append(parent)

    def _path(self, target: str, source: str) -> tuple[list[str], list[str]]:
        """Frames from source up to (excluding) the common ancestor, and likewise from target."""
        up_source, up_target = self._chain(source), self._chain(target)
        common = next((f for f in up_source if f in up_target), None)
        if common is None:
            raise LookupError(
                f"no transform from {source!r} to {target!r}: they are in different trees "
                f"(roots {up_source[-1]!r} and {up_target[-1]!r})"
            )
        return up_source[: up_source.index(common)], up_target[: up_target.index(common)]

    def _link(self, child: str, stamp_ns: int | None) -> Transform:
        if child in self._static:
            return self._static[child][1]
        history = self._dynamic[child]
        stamps = history.stamps
        if stamp_ns is None:
            return history.transforms[-1]
        i = bisect.bisect_left(stamps, stamp_ns)
        if i < len(stamps) and stamps[i] == stamp_ns:
            return history.transforms[i]
        if 0 < i < len(stamps):
            fraction = (stamp_ns - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
            return interpolate(history.transforms[i - 1], history.transforms[i], fraction)
        nearest = 0 if i == 0 else len(stamps) - 1
        if abs(stamps[nearest] - stamp_ns) <= self._tolerance_ns:
            return history.transforms[nearest]
        when = "before the first" if i == 0 else "after the last"
        raise LookupError(
            f"{history.parent} -> {child}: stamp {stamp_ns} ns is "
            f"{abs(stamps[nearest] - stamp_ns) / 1e9:.3f} s {when} sample ({stamps[0]}..{stamps[-1]} ns), "
            f"beyond the {self._tolerance_ns / 1e9:.3f} s tolerance"
        )

    def lookup(self, target_frame: str, source_frame: str, stamp_ns: int | None) -> Transform:
        """The transform mapping points in ``source_frame`` into ``target_frame`` at ``stamp_ns``.

        ``stamp_ns=None`` uses each link's newest sample. Raises :class:`LookupError` when the
        frames are unknown, unconnected, or a link has no samples close enough to ``stamp_ns``.
        """
        target_frame, source_frame = _frame(target_frame), _frame(source_frame)
        known = self.frames
        for name in (target_frame, source_frame):
            if name not in known:
                raise LookupError(f"unknown frame {name!r}; known: {sorted(known)}")
        up_source, up_target = self._path(target_frame, source_frame)
        source_in_common = identity()
        for child in up_source:
            source_in_common = compose(self._link(child, stamp_ns), source_in_common)
        target_in_common = identity()
        for child in up_target:
            target_in_common = compose(self._link(child, stamp_ns), target_in_common)
        return compose(invert(target_in_common), source_in_common)

    def can_transform(self, target_frame: str, source_frame: str, stamp_ns: int | None) -> bool:
        """Whether :meth:`lookup` would succeed."""
        try:
            self.lookup(target_frame, source_frame, stamp_ns)
        except LookupError:
            return False
        return True

    def newest_stamp_ns(self, target_frame: str, source_frame: str) -> int | None:
        """The newest stamp every dynamic link between the frames has reached.

        ``None`` when the frames are not connected; a very large value when every link is static.
        Lets a consumer hold a message until its stamp can be interpolated rather than extrapolated.
        """
        target_frame, source_frame = _frame(target_frame), _frame(source_frame)
        if not {target_frame, source_frame} <= self.frames:
            return None
        try:
            up_source, up_target = self._path(target_frame, source_frame)
        except LookupError:
            return None
        newest = [self._dynamic[c].stamps[-1] for c in (*up_source, *up_target) if c in self._dynamic]
        return min(newest, default=2**63 - 1)


def add_tf_message(buffer: TransformBuffer, message: TFMessage, *, static: bool = False) -> int:
    """Feed a tf2_msgs/TFMessage into ``buffer``; return the number of transforms taken."""
    for item in message.transforms:
        t, q = item.transform.translation, item.transform.rotation
        buffer.set_transform(
            item.header.frame_id,
            item.child_frame_id,
            messages.stamp_ns(item.header),
            (t.x, t.y, t.z),
            (q.x, q.y, q.z, q.w),
            static=static,
        )
    return len(message.transforms)


def add_odometry(buffer: TransformBuffer, message: Odometry) -> None:
    """Feed a nav_msgs/Odometry pose (``header.frame_id`` -> ``child_frame_id``) into ``buffer``."""
    p, q = message.pose.pose.position, message.pose.pose.orientation
    buffer.set_transform(message.header.frame_id, message.child_frame_id, messages.stamp_ns(message.header),
                         (p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
