"""The floor-plan service's error type."""

from __future__ import annotations


class FloorPlanError(ValueError):
    """Input the floor-plan stage cannot use: empty, unknown-only or malformed maps, bad settings."""
