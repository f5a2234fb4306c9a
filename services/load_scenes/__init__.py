"""Load scenes: what stands in each rack bay, as scene graphs by knowledge-supervised MCMC (seed 003, ch. 4)."""

from services.load_scenes.boxes import Skipped
from services.load_scenes.context import ContextResult, ContextSettings, infer_context, log_prior
from services.load_scenes.errors import LoadScenesError, SceneError
from services.load_scenes.estimation import RackView, bays_from_bins, estimate_boxes, merge_views
from services.load_scenes.frames import Intrinsics, decode_depth, intrinsics_from_camera_info
from services.load_scenes.inference import InferenceSettings, SceneInference, infer_bay_scene, infer_scene
from services.load_scenes.likelihood import LikelihoodSettings, prepare_rays, scene_log_likelihood
from services.load_scenes.occupancy import (
    BinEvidence,
    OccupancySettings,
    bin_evidence,
    bin_occupancy,
    fuse_occupancy,
)
from services.load_scenes.predicates import Evidence, evidence_predicates, support_relations

__all__ = [
    "BinEvidence",
    "ContextResult",
    "ContextSettings",
    "Evidence",
    "InferenceSettings",
    "Intrinsics",
    "LikelihoodSettings",
    "LoadScenesError",
    "OccupancySettings",
    "RackView",
    "SceneError",
    "SceneInference",
    "Skipped",
    "bays_from_bins",
    "bin_evidence",
    "bin_occupancy",
    "decode_depth",
    "estimate_boxes",
    "evidence_predicates",
    "fuse_occupancy",
    "infer_bay_scene",
    "infer_context",
    "infer_scene",
    "intrinsics_from_camera_info",
    "log_prior",
    "merge_views",
    "prepare_rays",
    "scene_log_likelihood",
    "support_relations",
]
