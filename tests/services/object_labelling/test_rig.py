"""A frame waits for tf to reach its stamp, so its camera pose is interpolated, not the last one held."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from services.object_labelling.pairing import FramePair
from services.object_labelling.rig import AwaitingPose
from shared.transforms import Transform, TransformBuffer


def _pair(stamp_ns: int) -> FramePair[Any]:
    colour = SimpleNamespace(header=SimpleNamespace(frame_id="camera"))
    return FramePair("robot1", stamp_ns, colour, colour)


def _robot_at(buffer: TransformBuffer, stamp_ns: int, x_m: float) -> None:
    buffer.set_transform("map", "camera", stamp_ns, (x_m, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def test_a_frame_ahead_of_tf_waits_for_it_then_gets_the_interpolated_pose() -> None:
    buffer = TransformBuffer(extrapolation_s=0.1)
    rig = SimpleNamespace(transforms=buffer)
    _robot_at(buffer, 1_000_000_000, 0.0)
    awaiting = AwaitingPose(map_frame="map", wait_s=0.5)
    awaiting.add(_pair(1_050_000_000), now_s=0.0)  # 50 ms after the last tf: inside the hold tolerance
    assert list(awaiting.due(lambda _: rig, 0.01)) == [] and awaiting  # type: ignore[arg-type, return-value]
    _robot_at(buffer, 1_100_000_000, 1.0)  # the robot moved 1 m in those 100 ms
    [(pair, pose)] = list(awaiting.due(lambda _: rig, 0.02))  # type: ignore[arg-type, return-value]
    assert pair.stamp_ns == 1_050_000_000
    assert isinstance(pose, Transform) and np.allclose(pose.translation, (0.5, 0.0, 0.0))


def test_a_frame_whose_tf_never_comes_gets_the_held_pose_or_an_error_after_the_wait() -> None:
    buffer = TransformBuffer(extrapolation_s=0.1)
    rig = SimpleNamespace(transforms=buffer)
    _robot_at(buffer, 1_000_000_000, 0.0)
    awaiting = AwaitingPose(map_frame="map", wait_s=0.5)
    awaiting.add(_pair(1_050_000_000), now_s=0.0)
    awaiting.add(_pair(2_000_000_000)._replace(namespace="robot2"), now_s=0.0)
    done = {p.namespace: pose for p, pose in awaiting.due(lambda _: rig, 0.6)}  # type: ignore[arg-type, return-value]
    held = done["robot1"]
    assert isinstance(held, Transform) and np.allclose(held.translation, (0.0, 0.0, 0.0))  # within tolerance: held
    assert isinstance(done["robot2"], LookupError) and not awaiting  # a second beyond it: an error
