import math
from typing import Any

import numpy as np
import pytest

from services.semantic_fusion import SemanticFusionError, observation_from_arrays, observation_from_message
from shared import messages

NAMES = ["wall", "rack", "human"]


def _message(**overrides: object) -> Any:
    cls = messages.message_class
    fields = {
        "bearings": np.array([0.0, 0.5], np.float32), "ranges": np.array([2.0, 3.0], np.float32),
        "heights": np.array([3.0, 1.8], np.float32), "labels": np.array([0, 2], np.uint8),
        "confidences": np.array([0.9, 0.6], np.float32), "class_names": NAMES,
    }
    fields.update(overrides)
    yaw = math.pi / 2
    pose = cls("geometry_msgs/msg/Pose")(
        position=cls("geometry_msgs/msg/Point")(x=1.0, y=2.0, z=1.0),
        orientation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))
    header = cls("std_msgs/msg/Header")(stamp=cls("builtin_interfaces/msg/Time")(sec=5, nanosec=7), frame_id="cam")
    msg = cls(messages.ANNOTATED_SCAN)(header=header, camera_pose=pose, **fields)
    return messages.deserialize(messages.serialize(msg, messages.ANNOTATED_SCAN), messages.ANNOTATED_SCAN)


def test_observation_from_message_places_cones_in_camera_frame() -> None:
    obs = observation_from_message(_message())
    assert obs.stamp_ns == 5_000_000_007
    np.testing.assert_allclose(obs.camera_pose, [1.0, 2.0, math.pi / 2], atol=1e-9)
    np.testing.assert_allclose(obs.points_xy[0], [2.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(obs.points_xy[1], [3.0 * math.cos(0.5), 3.0 * math.sin(0.5)], atol=1e-5)
    assert obs.columns.tolist() == [1, 6]  # wall, human in distribution order


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"ranges": np.array([2.0], np.float32)}, "differ in length"),
        ({"ranges": np.array([2.0, np.nan], np.float32)}, "non-finite ranges"),
        ({"heights": np.array([np.inf, 1.0], np.float32)}, "non-finite heights"),
        ({"labels": np.array([0, 3], np.uint8)}, "labels must index class_names"),
        ({"confidences": np.array([0.5, 1.5], np.float32)}, "confidences outside"),
        ({"ranges": np.array([0.0, 1.0], np.float32)}, "ranges outside"),
        ({"class_names": ["wall", "", "human"]}, "cannot label"),
    ],
)
def test_observation_from_message_rejects_malformed_scans(overrides: dict[str, object], match: str) -> None:
    with pytest.raises(SemanticFusionError, match=match):
        observation_from_message(_message(**overrides))


def test_observation_rejects_stamps_out_of_order() -> None:
    with pytest.raises(SemanticFusionError, match="out of order"):
        observation_from_message(_message(), previous_stamp_ns=5_000_000_007)


def test_observation_rejects_non_finite_pose() -> None:
    with pytest.raises(SemanticFusionError, match="camera pose"):
        observation_from_arrays(1, (0.0, math.nan, 0.0), [0.0], [1.0], [1.0], [0], [0.5], ["wall"])


def test_observation_accepts_a_scan_without_cones() -> None:
    obs = observation_from_arrays(1, (0.0, 0.0, 0.0), [], [], [], np.array([], np.uint8), [], ["wall"])
    assert obs.points_xy.shape == (0, 2)
