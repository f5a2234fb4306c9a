"""Object labelling: RGB-D object proposals from a range/height contour, CNN features and SVM classes."""

from services.object_labelling.camera import (
    CameraIntrinsics,
    depth_to_points,
    intrinsics_from_camera_info,
    make_intrinsics,
    subsample,
)
from services.object_labelling.classifier import UNKNOWN, LabelModel, SvmBank, best_class
from services.object_labelling.cnn import FEATURE_SIZE, EfficientNetLite0, resize_for_cnn
from services.object_labelling.crops import ROI_PAD_FRACTION, box_iou, crop_box
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.frames import decode_depth, decode_rgb
from services.object_labelling.ground_plane import GroundCheck, GroundPlane, check_ground_plane, fit_ground_plane
from services.object_labelling.labeller import FrameLabels, LabelledObject, ObjectLabeller
from services.object_labelling.range_scan import MissingCones, RangeHeightScan, floor_axes, range_height_scan
from services.object_labelling.retrieval import DEFAULT_PRIORS, PriorDatabase, Proposal, border_weights, retrieve
from services.object_labelling.segments import Segment, boundaries, segments
from services.object_labelling.torch_weights import load_state_dict, verify_name_hash

__all__ = [
    "DEFAULT_PRIORS",
    "FEATURE_SIZE",
    "ROI_PAD_FRACTION",
    "UNKNOWN",
    "CameraIntrinsics",
    "EfficientNetLite0",
    "FrameLabels",
    "GroundCheck",
    "GroundPlane",
    "LabelModel",
    "LabelledObject",
    "MissingCones",
    "ObjectLabeller",
    "ObjectLabellingError",
    "PriorDatabase",
    "Proposal",
    "RangeHeightScan",
    "Segment",
    "SvmBank",
    "best_class",
    "border_weights",
    "boundaries",
    "box_iou",
    "check_ground_plane",
    "crop_box",
    "decode_depth",
    "decode_rgb",
    "depth_to_points",
    "fit_ground_plane",
    "floor_axes",
    "intrinsics_from_camera_info",
    "load_state_dict",
    "make_intrinsics",
    "range_height_scan",
    "resize_for_cnn",
    "retrieve",
    "segments",
    "subsample",
    "verify_name_hash",
]
