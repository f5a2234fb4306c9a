"""The occupancy-mapping service's error type."""

from __future__ import annotations


class OccupancyMappingError(ValueError):
    """Input the occupancy mapper cannot use: malformed scans, poses, maps or bags."""
