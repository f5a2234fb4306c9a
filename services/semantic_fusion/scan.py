"""Validate aisle_msgs/AnnotatedScan messages and turn them into labelled points."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from services.semantic_fusion.classes import class_columns
from services.semantic_fusion.errors import SemanticFusionError
from shared import messages
from shared.transforms import yaw_from_quaternion


class ScanObservation(NamedTuple):
    """One validated annotated scan, its points in the camera's planar frame.

    Attributes
    ----------
    stamp_ns : int
        Header stamp, nanoseconds.
    camera_pose : (3,) float64
        Camera (x, y, yaw) in the map frame as the robot estimated it, metres and radians.
    points_xy : (n, 2) float64
        Cone end points in the camera frame (x along the optical axis projected on the floor), metres.
    heights : (n,) float32
        Height of what each cone saw, metres.
    columns : (n,) intp
        Distribution column of each cone's label (see :mod:`services.semantic_fusion.classes`).
    confidences : (n,) float32
        Labeller confidence of each cone, in [0, 1].
    """

    stamp_ns: int
    camera_pose: npt.NDArray[np.float64]
    points_xy: npt.NDArray[np.float64]
    heights: npt.NDArray[np.float32]
    columns: npt.NDArray[np.intp]
    confidences: npt.NDArray[np.float32]


def observation_from_arrays(
    stamp_ns: int,
    camera_pose: npt.ArrayLike,
    bearings_rad: npt.ArrayLike,
    ranges_m: npt.ArrayLike,
    heights_m: npt.ArrayLike,
    labels: npt.ArrayLike,
    confidences: npt.ArrayLike,
    class_names: Sequence[str],
    *,
    previous_stamp_ns: int | None = None,
) -> ScanObservation:
    """Validate the fields of an annotated scan and return its labelled points.

    Parameters
    ----------
    stamp_ns : int
        Scan stamp, nanoseconds; must be later than ``previous_stamp_ns`` when that is given.
    camera_pose : (3,) array_like
        Camera (x, y, yaw) in the map frame, metres and radians.
    bearings_rad, ranges_m, heights_m : (n,) array_like
        Per cone: bearing in the camera frame (radians), range (metres, > 0), height (metres, >= 0).
    labels : (n,) array_like of int
        Index of each cone's class in ``class_names``.
    confidences : (n,) array_like
        Labeller confidence per cone, in [0, 1].
    class_names : sequence of str
        Names the labels index into.

    Raises
    ------
    SemanticFusionError
        Arrays of different lengths, non-finite values, ranges <= 0, negative heights,
        confidences outside [0, 1], labels outside ``class_names``, a stamp not after
        ``previous_stamp_ns``, or a non-finite pose.
    """
    if previous_stamp_ns is not None and stamp_ns <= previous_stamp_ns:
        raise SemanticFusionError(
            f"scan stamp {stamp_ns} ns is not after the previous scan's {previous_stamp_ns} ns (out of order)"
        )
    pose = np.asarray(camera_pose, dtype=np.float64).reshape(-1)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise SemanticFusionError(f"camera pose must be 3 finite numbers (x, y, yaw), got {pose.tolist()}")
    fields = {
        "bearings": np.asarray(bearings_rad, dtype=np.float64).reshape(-1),
        "ranges": np.asarray(ranges_m, dtype=np.float64).reshape(-1),
        "heights": np.asarray(heights_m, dtype=np.float64).reshape(-1),
        "labels": np.asarray(labels).reshape(-1),
        "confidences": np.asarray(confidences, dtype=np.float64).reshape(-1),
    }
    lengths = {name: value.size for name, value in fields.items()}
    if len(set(lengths.values())) != 1:
        raise SemanticFusionError(f"per-cone arrays differ in length: {lengths}")
    for name in ("bearings", "ranges", "heights", "confidences"):
        bad = ~np.isfinite(fields[name])
        if bad.any():
            raise SemanticFusionError(f"{int(bad.sum())} non-finite {name}, first at cone {int(np.argmax(bad))}")
    _check_range(fields["ranges"], "ranges", low=0.0, low_inclusive=False)
    _check_range(fields["heights"], "heights", low=0.0)
    _check_range(fields["confidences"], "confidences", low=0.0, high=1.0)
    label_ids = fields["labels"]
    if label_ids.size and (not np.issubdtype(label_ids.dtype, np.integer) or label_ids.min() < 0
                           or label_ids.max() >= len(class_names)):
        raise SemanticFusionError(
            f"labels must index class_names ({len(class_names)} names), got values "
            f"{label_ids.min()}..{label_ids.max()}"
        )
    columns = class_columns(list(class_names))[label_ids.astype(np.intp)] if label_ids.size else (
        np.empty(0, dtype=np.intp))
    bearings, ranges = fields["bearings"], fields["ranges"]
    points = np.stack([ranges * np.cos(bearings), ranges * np.sin(bearings)], axis=1)
    return ScanObservation(int(stamp_ns), pose, points, fields["heights"].astype(np.float32), columns,
                           fields["confidences"].astype(np.float32))


def _check_range(values: npt.NDArray[np.float64], name: str, *, low: float, high: float = math.inf,
                 low_inclusive: bool = True) -> None:
    below = values < low if low_inclusive else values <= low
    bad = below | (values > high)
    if bad.any():
        first = int(np.argmax(bad))
        relation = ">=" if low_inclusive else ">"
        raise SemanticFusionError(
            f"{int(bad.sum())} {name} outside {relation} {low}"
            + (f" and <= {high}" if math.isfinite(high) else "")
            + f", first at cone {first}: {values[first]}"
        )


def observation_from_message(message: Any, *, previous_stamp_ns: int | None = None) -> ScanObservation:
    """Validate an aisle_msgs/AnnotatedScan and return its labelled points.

    The camera pose is projected onto the floor: its position's x and y and the heading of its
    +x (optical) axis. Raises :class:`SemanticFusionError` as :func:`observation_from_arrays`
    does, and for an unusable orientation quaternion.
    """
    stamp_ns = messages.stamp_ns(message.header)
    p, q = message.camera_pose.position, message.camera_pose.orientation
    try:
        yaw = yaw_from_quaternion((q.x, q.y, q.z, q.w))
    except ValueError as err:
        raise SemanticFusionError(f"camera pose orientation: {err}") from err
    return observation_from_arrays(
        stamp_ns, (p.x, p.y, yaw), message.bearings, message.ranges, message.heights, message.labels,
        message.confidences, list(message.class_names), previous_stamp_ns=previous_stamp_ns,
    )


class RangeScan(NamedTuple):
    """One planar range scan (a lidar's), for scan matching only: it adds nothing to the grid.

    ``pose`` (3,) float64 is the scanner's (x, y, yaw) in the map frame as the robot estimated it
    (the same odometry as the annotated scans' camera poses); ``points_xy`` (n, 2) float64 are the
    returns in the scanner's frame, metres.
    """

    stamp_ns: int
    pose: npt.NDArray[np.float64]
    points_xy: npt.NDArray[np.float64]


def range_scan_from_arrays(stamp_ns: int, pose: npt.ArrayLike, angle_min_rad: float, angle_increment_rad: float,
                           ranges_m: npt.ArrayLike, *, range_min_m: float = 0.0,
                           range_max_m: float = math.inf) -> RangeScan:
    """Validate a planar range scan (sensor_msgs/LaserScan fields) and return its returns as points.

    Beams without a return (inf, NaN, outside ``[range_min_m, range_max_m]``, as REP 117 allows)
    are dropped, not errors.

    Raises
    ------
    SemanticFusionError
        A non-finite pose or angles, or a non-positive angle increment.
    """
    p = np.asarray(pose, dtype=np.float64).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise SemanticFusionError(f"scanner pose must be 3 finite numbers (x, y, yaw), got {p.tolist()}")
    if not (math.isfinite(angle_min_rad) and math.isfinite(angle_increment_rad) and angle_increment_rad > 0):
        raise SemanticFusionError(f"unusable scan angles: min {angle_min_rad}, increment {angle_increment_rad}")
    ranges = np.asarray(ranges_m, dtype=np.float64).reshape(-1)
    bearings = angle_min_rad + angle_increment_rad * np.arange(ranges.size)
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(ranges) & (ranges >= max(range_min_m, 1e-3)) & (ranges <= range_max_m)
    r, b = ranges[keep], bearings[keep]
    return RangeScan(int(stamp_ns), p, np.stack([r * np.cos(b), r * np.sin(b)], axis=1))
