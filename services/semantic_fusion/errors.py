"""The semantic-fusion service's error type."""

from __future__ import annotations


class SemanticFusionError(ValueError):
    """Input the semantic fusion cannot use: malformed annotated scans, poses, grids or settings."""
