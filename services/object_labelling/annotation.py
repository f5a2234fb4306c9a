"""From one frame's labels to per-cone annotations, the camera's floor pose and map-frame detections.

The scan's bearings and ranges live in the camera's *floor frame*: origin at the camera, x the
optical axis projected onto the ground plane, y to the left on the plane, z up along its normal.
Its pose in the map frame (optical pose from TF composed with the floor frame) is what an
AnnotatedScan carries, so a consumer places cone ``i`` at ``pose * (r cos b, r sin b)``.

Cones of a classified object get its class; other obstacle cones get the whole-image class when
exactly one is present (rack or gate), else ``unknown``. Cones that saw only floor or nothing are
left out. Confidences are the calibrated (Platt) probabilities of the label given: the object's
class, the whole-image class, or for ``unknown`` one minus the best class's probability.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.object_labelling.classifier import UNKNOWN
from services.object_labelling.ground_plane import GroundPlane
from services.object_labelling.labeller import FrameLabels
from services.object_labelling.objects import Detection
from services.object_labelling.range_scan import floor_axes
from shared.transforms import Transform, compose, from_matrix, to_matrix


class ConeAnnotations(NamedTuple):
    """The cones worth publishing: indices into the scan (k,), label index into class names (k,) uint8,
    confidence in [0, 1] (k,) float32."""

    cones: npt.NDArray[np.intp]
    labels: npt.NDArray[np.uint8]
    confidences: npt.NDArray[np.float32]


def annotate_cones(frame: FrameLabels, class_names: tuple[str, ...]) -> ConeAnnotations:
    """Per-cone label and confidence of every cone with a finite obstacle range.

    Parameters
    ----------
    frame
        The labeller's result for one frame.
    class_names
        Label names; must hold ``"unknown"`` and every class the labeller and the scene can give.
    """
    index = {name: i for i, name in enumerate(class_names)}
    ranges = frame.scan.ranges_m
    n = ranges.shape[0]
    if len(frame.scene_present) == 1:
        background = frame.scene_present[0]
        background_confidence = frame.scene[background]
    else:
        background = UNKNOWN
        background_confidence = 1.0 - max(frame.scene.values(), default=0.0) if not frame.scene_present else 0.0
    labels = np.full(n, index[background], dtype=np.uint8)
    confidences = np.full(n, background_confidence, dtype=np.float32)
    for obj in frame.objects:
        segment = obj.proposal.segment
        labels[segment.start : segment.stop] = index[obj.label]
        confidences[segment.start : segment.stop] = 1.0 - obj.probability if obj.label == UNKNOWN else obj.probability
    cones = np.flatnonzero(np.isfinite(ranges) & (ranges > 0))
    return ConeAnnotations(cones, labels[cones], confidences[cones])


def floor_frame(plane: GroundPlane) -> Transform:
    """The camera's floor frame as a transform into the optical frame (see the module docstring)."""
    up, forward, left = floor_axes(plane)
    matrix = np.eye(4)
    matrix[:3, :3] = np.column_stack((forward, left, up))
    return from_matrix(matrix)


def camera_floor_pose(optical_in_map: Transform, plane: GroundPlane) -> Transform:
    """Pose of the camera's floor frame in the map, from the optical frame's pose in the map."""
    return compose(optical_in_map, floor_frame(plane))


def detections(
    frame: FrameLabels,
    floor_in_map: Transform,
    plane: GroundPlane,
    *,
    classes: frozenset[str],
    stamp_ns: int,
    namespace: str,
) -> list[Detection]:
    """Map-frame floor positions of the frame's objects of ``classes``.

    An object is placed at the median floor point of the closest obstacle points of its cones,
    ``plane.offset`` below the camera (so the point lies on the floor).
    """
    to_map = to_matrix(floor_in_map)
    out = []
    for obj in frame.objects:
        if obj.label not in classes:
            continue
        segment = obj.proposal.segment
        forward = frame.scan.forward_m[segment.start : segment.stop]
        left = frame.scan.left_m[segment.start : segment.stop]
        finite = np.isfinite(forward) & np.isfinite(left)
        if not finite.any():
            continue
        local = np.array([np.median(forward[finite]), np.median(left[finite]), -plane.offset, 1.0])
        x, y = (to_map @ local)[:2]
        out.append(Detection(obj.label, float(x), float(y), obj.probability, stamp_ns, namespace, segment.width_m))
    return out

