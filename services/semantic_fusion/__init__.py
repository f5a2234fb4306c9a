"""Semantic fusion: labelled scans on a keyframe pose graph into a sparse semantic grid, with inference."""

from services.semantic_fusion.classes import (
    CLASS_COLOURS,
    DISTRIBUTION_CLASSES,
    DYNAMIC_CLASSES,
    N_CLASSES,
    class_columns,
)
from services.semantic_fusion.errors import SemanticFusionError
from services.semantic_fusion.evaluation import LabelAccuracy, absolute_trajectory_error, label_accuracy
from services.semantic_fusion.fusion import FusionSettings, SemanticFusion
from services.semantic_fusion.grid import GridCells, SemanticGrid, cell_indices, evidence_weights
from services.semantic_fusion.inference import (
    ENTROPY_ENCODING,
    LABEL_ENCODING,
    NO_ENTROPY,
    CellLabels,
    SemanticLayers,
    infer_labels,
    normalised_entropy,
    rasterise,
)
from services.semantic_fusion.pose_graph import Constraint, PoseGraph
from services.semantic_fusion.render import render_labels
from services.semantic_fusion.resume import evidence_for_entropy, seed_grid
from services.semantic_fusion.scan import (
    RangeScan,
    ScanObservation,
    observation_from_arrays,
    observation_from_message,
    range_scan_from_arrays,
)
from services.semantic_fusion.scan_matching import Alignment, ScanMatch, align_scans, match_scans

__all__ = [
    "CLASS_COLOURS",
    "DISTRIBUTION_CLASSES",
    "DYNAMIC_CLASSES",
    "ENTROPY_ENCODING",
    "LABEL_ENCODING",
    "NO_ENTROPY",
    "N_CLASSES",
    "Alignment",
    "CellLabels",
    "Constraint",
    "FusionSettings",
    "GridCells",
    "LabelAccuracy",
    "PoseGraph",
    "RangeScan",
    "ScanMatch",
    "ScanObservation",
    "SemanticFusion",
    "SemanticFusionError",
    "SemanticGrid",
    "SemanticLayers",
    "absolute_trajectory_error",
    "align_scans",
    "cell_indices",
    "class_columns",
    "evidence_for_entropy",
    "evidence_weights",
    "infer_labels",
    "label_accuracy",
    "match_scans",
    "normalised_entropy",
    "observation_from_arrays",
    "observation_from_message",
    "range_scan_from_arrays",
    "rasterise",
    "render_labels",
    "seed_grid",
]
