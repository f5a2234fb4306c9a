from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from services.pillar_mapping import PillarMappingError, map_pillars_from_bag, read_landmarks_csv
from services.pillar_mapping.evaluation import drive_aisles, map_rmse
from services.pillar_mapping.synthetic import default_camera, rack_region, rack_scene, render_fisheye
from shared.messages import CAMERA_INFO, IMAGE, POSE_STAMPED, TYPESTORE, message_class, serialize
from shared.transforms import quaternion_from_yaw

S = 1_000_000_000


def _header(ns: int, frame: str) -> Any:
    stamp = message_class("builtin_interfaces/msg/Time")(sec=ns // S, nanosec=ns % S)
    return message_class("std_msgs/msg/Header")(stamp=stamp, frame_id=frame)


def _pose(ns: int, x: float, y: float, yaw: float) -> Any:
    q = quaternion_from_yaw(yaw)
    return message_class(POSE_STAMPED)(
        header=_header(ns, "map"),
        pose=message_class("geometry_msgs/msg/Pose")(
            position=message_class("geometry_msgs/msg/Point")(x=x, y=y, z=0.0),
            orientation=message_class("geometry_msgs/msg/Quaternion")(x=q[0], y=q[1], z=q[2], w=q[3]),
        ),
    )


def _info(ns: int, camera: Any) -> Any:
    roi = message_class("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return message_class(CAMERA_INFO)(
        header=_header(ns, "fisheye_optical"),
        height=camera.height,
        width=camera.width,
        distortion_model="equidistant",
        d=camera.d.copy(),
        k=camera.k.ravel().copy(),
        r=np.eye(3).ravel(),
        p=np.zeros(12),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def _image(ns: int, pixels: np.ndarray) -> Any:
    h, w, _ = pixels.shape
    return message_class(IMAGE)(
        header=_header(ns, "fisheye_optical"),
        height=h,
        width=w,
        encoding="rgb8",
        is_bigendian=0,
        step=3 * w,
        data=np.ascontiguousarray(pixels[..., ::-1]).ravel(),
    )


def _write_bag(path: Path, layout: Any) -> None:
    rng = np.random.default_rng(4)
    camera = default_camera(size_px=400)
    scene = rack_scene(layout, rng)
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        image_c = writer.add_connection("/robot1/fisheye/image_raw", IMAGE, typestore=TYPESTORE)
        info_c = writer.add_connection("/robot1/fisheye/camera_info", CAMERA_INFO, typestore=TYPESTORE)
        pose_c = writer.add_connection("/robot1/ground_truth/pose", POSE_STAMPED, typestore=TYPESTORE)
        for k, pose in enumerate(drive_aisles(layout, 0.3, overshoot_m=1.0)):
            ns = S + k * S // 5
            writer.write(pose_c, ns - S // 20, serialize(_pose(ns - S // 20, *pose), POSE_STAMPED))
            writer.write(pose_c, ns + S // 20, serialize(_pose(ns + S // 20, *pose), POSE_STAMPED))
            pixels, _ = render_fisheye(camera, scene, pose, rng)
            writer.write(info_c, ns, serialize(_info(ns, camera), CAMERA_INFO))
            writer.write(image_c, ns, serialize(_image(ns, pixels), IMAGE))


@pytest.mark.slow
def test_map_pillars_from_bag_maps_the_uprights_along_the_driven_aisle(tmp_path: Path) -> None:
    layout = rack_region(aisles=1, bays=4)
    bag = tmp_path / "bag"
    _write_bag(bag, layout)
    result = map_pillars_from_bag(bag, tmp_path / "out")
    assert result.frames_used > 20
    table = read_landmarks_csv(tmp_path / "out" / "pillars.csv")
    rmse, matched, extra = map_rmse(table[:, :2], layout.uprights)
    assert matched >= 0.95 * len(layout.uprights)
    assert extra == 0
    assert rmse <= 0.05


def test_map_pillars_from_bag_names_the_missing_topic(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        c = writer.add_connection("/robot1/ground_truth/pose", POSE_STAMPED, typestore=TYPESTORE)
        writer.write(c, S, serialize(_pose(S, 0.0, 0.0, 0.0), POSE_STAMPED))
    with pytest.raises(PillarMappingError, match="no image topic"):
        map_pillars_from_bag(bag)


def test_map_pillars_from_bag_rejects_a_missing_bag(tmp_path: Path) -> None:
    with pytest.raises(PillarMappingError, match="does not exist"):
        map_pillars_from_bag(tmp_path / "nope")
