"""Grid decomposition: dominant orientations, radiogram lines, cells, place labels and regions.

The store records (``records.py``: the map store's types, SQLAlchemy behind them) and the map files
(``mapfile.py``: Pillow and YAML behind them) are imported when one of their names is first asked for:
decomposing a map needs none of them.
"""

from typing import TYPE_CHECKING

from services.grid_decomposition.change import changed_fraction, occupancy_classes
from services.grid_decomposition.cogency import EdgeCogency, close_doorways, edge_cogency, wall_evidence
from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.evaluation import IpaScores, ground_truth_rooms, ipa_scores
from services.grid_decomposition.faces import FaceGeometry, face_geometry
from services.grid_decomposition.labelling import Evidence, FaceLabels, assign_labels, evidence_labels, face_categories
from services.grid_decomposition.necks import split_at_necks
from services.grid_decomposition.orientations import Gradients, dominant_orientations, oriented_gradients
from services.grid_decomposition.overview import overview_image
from services.grid_decomposition.pipeline import Decomposition, Resolution, decompose
from services.grid_decomposition.places import cast_rays, categorize_places, raycast_features
from services.grid_decomposition.radiogram import Line, Radiogram, line_offsets, radiogram
from services.grid_decomposition.regions import RegionInfo, face_regions, region_topology
from services.grid_decomposition.semantics import (
    Connection,
    link_connection,
    parse_label,
    parse_label_table,
)
from services.grid_decomposition.subdivision import LineGroup, Subdivision, subdivide
from services.grid_decomposition.templates import Template, match_templates, template_branches
from services.grid_decomposition.texture import gabor_features, segment_texture_regions

if TYPE_CHECKING:
    from services.grid_decomposition.mapfile import (
        decompose_map_file,
        layout_features,
        parse_label_overrides,
        read_map_file,
        write_outputs,
    )
    from services.grid_decomposition.records import (
        PLACE_LABELS,
        PLACE_SEGMENTS,
        REGION_FEATURE_KINDS,
        decomposition_features,
        decomposition_layers,
        decomposition_topology,
        region_key,
    )

_RECORDS = frozenset(
    {
        "PLACE_LABELS",
        "PLACE_SEGMENTS",
        "REGION_FEATURE_KINDS",
        "decomposition_features",
        "decomposition_layers",
        "decomposition_topology",
        "region_key",
    }
)


_MAP_FILES = frozenset(
    {"decompose_map_file", "layout_features", "parse_label_overrides", "read_map_file", "write_outputs"}
)


def __getattr__(name: str) -> object:
    if name in _RECORDS:
        from services.grid_decomposition import records

        return getattr(records, name)
    if name in _MAP_FILES:
        from services.grid_decomposition import mapfile

        return getattr(mapfile, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "PLACE_LABELS",
    "PLACE_SEGMENTS",
    "REGION_FEATURE_KINDS",
    "Connection",
    "Decomposition",
    "DecompositionError",
    "EdgeCogency",
    "Evidence",
    "FaceGeometry",
    "FaceLabels",
    "Gradients",
    "IpaScores",
    "Line",
    "LineGroup",
    "Radiogram",
    "RegionInfo",
    "Resolution",
    "Subdivision",
    "Template",
    "assign_labels",
    "cast_rays",
    "categorize_places",
    "changed_fraction",
    "close_doorways",
    "decompose",
    "decompose_map_file",
    "decomposition_features",
    "decomposition_layers",
    "decomposition_topology",
    "dominant_orientations",
    "edge_cogency",
    "evidence_labels",
    "face_categories",
    "face_geometry",
    "face_regions",
    "gabor_features",
    "ground_truth_rooms",
    "ipa_scores",
    "layout_features",
    "line_offsets",
    "link_connection",
    "match_templates",
    "occupancy_classes",
    "oriented_gradients",
    "overview_image",
    "parse_label",
    "parse_label_overrides",
    "parse_label_table",
    "radiogram",
    "raycast_features",
    "read_map_file",
    "region_key",
    "region_topology",
    "segment_texture_regions",
    "split_at_necks",
    "subdivide",
    "template_branches",
    "wall_evidence",
    "write_outputs",
]
