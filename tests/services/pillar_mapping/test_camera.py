from pathlib import Path

import cv2
import numpy as np
import pytest

from services.pillar_mapping import (
    PillarMappingError,
    camera_from_info,
    pixel_angles,
    project_angles,
    read_camera_info_yaml,
)

INFO = {
    "image_width": 640,
    "image_height": 480,
    "distortion_model": "equidistant",
    "camera_matrix": {"rows": 3, "cols": 3, "data": [200.0, 0, 320, 0, 201.0, 240, 0, 0, 1]},
    "distortion_coefficients": {"rows": 1, "cols": 4, "data": [0.02, -0.01, 0.003, -0.0005]},
}


def test_camera_from_info_reads_calibration_yaml(tmp_path: Path) -> None:
    import yaml

    path = tmp_path / "ci.yaml"
    path.write_text(yaml.safe_dump(INFO))
    camera = read_camera_info_yaml(path)
    assert camera.width == 640 and camera.height == 480
    assert camera.principal_point == (320.0, 240.0)
    assert camera.d.tolist() == [0.02, -0.01, 0.003, -0.0005]


def test_pixel_angles_invert_the_projection_beyond_ninety_degrees() -> None:
    camera = camera_from_info(INFO)
    theta = np.linspace(0.01, np.deg2rad(92), 50)
    azimuth = np.linspace(-3, 3, 50)
    uv = project_angles(camera, theta, azimuth)
    back_theta, back_azimuth = pixel_angles(camera, uv[:, 0], uv[:, 1])
    assert np.allclose(back_theta, theta, atol=1e-9)
    assert np.allclose(back_azimuth, azimuth, atol=1e-9)


def test_projection_agrees_with_opencv_fisheye() -> None:
    camera = camera_from_info(INFO)
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-1, 1, (20, 2)), np.ones(20)])
    expected, _ = cv2.fisheye.projectPoints(points[None], np.zeros(3), np.zeros(3), camera.k, camera.d)
    theta = np.arctan(np.hypot(points[:, 0], points[:, 1]))
    ours = project_angles(camera, theta, np.arctan2(points[:, 1], points[:, 0]))
    assert np.allclose(ours, expected[0], atol=1e-6)


def test_camera_from_info_rejects_a_pinhole_model() -> None:
    with pytest.raises(PillarMappingError, match="not equidistant"):
        camera_from_info({**INFO, "distortion_model": "plumb_bob"})


def test_camera_from_info_rejects_missing_coefficients() -> None:
    bad = {**INFO, "distortion_coefficients": {"data": [0.1, 0.2]}}
    with pytest.raises(PillarMappingError, match="4 finite coefficients"):
        camera_from_info(bad)
