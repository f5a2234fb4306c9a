"""The load-scene stage's error type."""

from __future__ import annotations


class LoadScenesError(ValueError):
    """Input the load-scene stage cannot use: malformed depth images, camera poses, bins or rack models."""
