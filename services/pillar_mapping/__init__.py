"""Pillar mapping: uprights seen by a downward fisheye, mapped by bearing-only EKF, fitted with rows and bins.

The names below are imported from their modules on first use (PEP 562), so ``aisle racks fit`` does not pay for the
camera, bag and smoothing modules (rosbags, GTSAM) it does not run.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from services.pillar_mapping.bag import PillarMapResult, image_bgr, map_pillars_from_bag
    from services.pillar_mapping.bins import StorageBin, storage_bins
    from services.pillar_mapping.camera import (
        FisheyeCamera,
        camera_from_info,
        pixel_angles,
        pixel_rays,
        project_angles,
        read_camera_info_yaml,
    )
    from services.pillar_mapping.detection import (
        BearingSignal,
        PillarDetections,
        bearing_signal,
        detect_pillars,
        detect_pillars_file,
    )
    from services.pillar_mapping.errors import PillarMappingError
    from services.pillar_mapping.frequency import Periodicity, dominant_spacing, projection_spectrum
    from services.pillar_mapping.hough import HoughPairs, dominant_orientations, hough_pairs, segment_aligned
    from services.pillar_mapping.landmark_io import read_landmarks_csv, write_landmarks_csv
    from services.pillar_mapping.layout import (
        RackLayout,
        fit_landmark_map,
        fit_layout,
        fit_racks,
        layout_features,
        layout_geojson,
    )
    from services.pillar_mapping.levels import RackProfile, bins_on_levels, profile_at, rack_profile
    from services.pillar_mapping.mapper import BearingOnlyMapper, FrameReport, LandmarkMap
    from services.pillar_mapping.mount import CameraMount, default_mount, mount_from_transform, vehicle_bearings
    from services.pillar_mapping.paint import PaintModel, paint_likelihood
    from services.pillar_mapping.rows import RackRow, fit_rack_rows
    from services.pillar_mapping.triangulation import Triangulation, triangulate_bearings

_MODULE_OF = {
    "BearingOnlyMapper": "mapper",
    "BearingSignal": "detection",
    "CameraMount": "mount",
    "FisheyeCamera": "camera",
    "FrameReport": "mapper",
    "HoughPairs": "hough",
    "LandmarkMap": "mapper",
    "PaintModel": "paint",
    "Periodicity": "frequency",
    "PillarDetections": "detection",
    "PillarMapResult": "bag",
    "PillarMappingError": "errors",
    "RackLayout": "layout",
    "RackProfile": "levels",
    "RackRow": "rows",
    "StorageBin": "bins",
    "Triangulation": "triangulation",
    "bearing_signal": "detection",
    "bins_on_levels": "levels",
    "camera_from_info": "camera",
    "default_mount": "mount",
    "detect_pillars": "detection",
    "detect_pillars_file": "detection",
    "dominant_orientations": "hough",
    "dominant_spacing": "frequency",
    "fit_landmark_map": "layout",
    "fit_layout": "layout",
    "fit_rack_rows": "rows",
    "fit_racks": "layout",
    "hough_pairs": "hough",
    "image_bgr": "bag",
    "layout_features": "layout",
    "layout_geojson": "layout",
    "map_pillars_from_bag": "bag",
    "mount_from_transform": "mount",
    "paint_likelihood": "paint",
    "pixel_angles": "camera",
    "pixel_rays": "camera",
    "profile_at": "levels",
    "project_angles": "camera",
    "projection_spectrum": "frequency",
    "rack_profile": "levels",
    "read_camera_info_yaml": "camera",
    "read_landmarks_csv": "landmark_io",
    "segment_aligned": "hough",
    "storage_bins": "bins",
    "triangulate_bearings": "triangulation",
    "vehicle_bearings": "mount",
    "write_landmarks_csv": "landmark_io",
}
"""The module each public name lives in."""


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


__all__ = [
    "BearingOnlyMapper",
    "BearingSignal",
    "CameraMount",
    "FisheyeCamera",
    "FrameReport",
    "HoughPairs",
    "LandmarkMap",
    "PaintModel",
    "Periodicity",
    "PillarDetections",
    "PillarMapResult",
    "PillarMappingError",
    "RackLayout",
    "RackProfile",
    "RackRow",
    "StorageBin",
    "Triangulation",
    "bearing_signal",
    "bins_on_levels",
    "camera_from_info",
    "default_mount",
    "detect_pillars",
    "detect_pillars_file",
    "dominant_orientations",
    "dominant_spacing",
    "fit_landmark_map",
    "fit_layout",
    "fit_rack_rows",
    "fit_racks",
    "hough_pairs",
    "image_bgr",
    "layout_features",
    "layout_geojson",
    "map_pillars_from_bag",
    "mount_from_transform",
    "paint_likelihood",
    "pixel_angles",
    "pixel_rays",
    "profile_at",
    "project_angles",
    "projection_spectrum",
    "rack_profile",
    "read_camera_info_yaml",
    "read_landmarks_csv",
    "segment_aligned",
    "storage_bins",
    "triangulate_bearings",
    "vehicle_bearings",
    "write_landmarks_csv",
]
