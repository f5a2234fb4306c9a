"""Occupancy mapping: log-odds grids from laser scans, offline building and map quality."""

from services.occupancy_mapping.errors import OccupancyMappingError
from services.occupancy_mapping.grid import OccupancyGrid
from services.occupancy_mapping.offline import BuildStats, build_map, build_map_with_stats
from services.occupancy_mapping.quality import WallAgreement, sharpness, wall_agreement
from services.occupancy_mapping.raycast import RayCasting
from services.occupancy_mapping.scan import ScanArrays, scan_angles, scan_arrays
from services.occupancy_mapping.scanmatch import MatchResult, ScanMatcher, likelihood_field, match_scan

__all__ = [
    "BuildStats",
    "MatchResult",
    "OccupancyGrid",
    "OccupancyMappingError",
    "RayCasting",
    "ScanArrays",
    "ScanMatcher",
    "WallAgreement",
    "build_map",
    "build_map_with_stats",
    "likelihood_field",
    "match_scan",
    "scan_angles",
    "scan_arrays",
    "sharpness",
    "wall_agreement",
]
