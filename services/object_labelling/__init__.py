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
from services.object_labelling.datasets import Crop, YoloSet, in_test_split, read_scene_labels, roi_crops, source_of
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.frames import decode_depth, decode_rgb
from services.object_labelling.ground_plane import GroundCheck, GroundPlane, check_ground_plane, fit_ground_plane
from services.object_labelling.labeller import FrameLabels, LabelledObject, ObjectLabeller
from services.object_labelling.range_scan import MissingCones, RangeHeightScan, floor_axes, range_height_scan
from services.object_labelling.retrieval import DEFAULT_PRIORS, PriorDatabase, Proposal, border_weights, retrieve
from services.object_labelling.segments import Segment, boundaries, segments
from services.object_labelling.torch_weights import load_state_dict, verify_name_hash
from services.object_labelling.training import (
    ROI_CLASSES,
    SCENE_CLASSES,
    Evaluation,
    evaluate_classifier,
    train_classifier,
)

__all__ = [
    "DEFAULT_PRIORS",
    "FEATURE_SIZE",
    "ROI_CLASSES",
    "SCENE_CLASSES",
    "UNKNOWN",
    "CameraIntrinsics",
    "Crop",
    "EfficientNetLite0",
    "Evaluation",
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
    "YoloSet",
    "best_class",
    "border_weights",
    "boundaries",
    "check_ground_plane",
    "decode_depth",
    "decode_rgb",
    "depth_to_points",
    "evaluate_classifier",
    "fit_ground_plane",
    "floor_axes",
    "in_test_split",
    "intrinsics_from_camera_info",
    "load_state_dict",
    "make_intrinsics",
    "range_height_scan",
    "read_scene_labels",
    "resize_for_cnn",
    "retrieve",
    "roi_crops",
    "segments",
    "source_of",
    "subsample",
    "train_classifier",
    "verify_name_hash",
]
