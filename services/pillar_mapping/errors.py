"""The pillar-mapping service's error type."""

from __future__ import annotations


class PillarMappingError(ValueError):
    """Input the pillar mapper cannot use: bad images, calibrations, bags or landmark maps."""
