"""The load-scene stage's error types."""

from __future__ import annotations


class LoadScenesError(ValueError):
    """Input the load-scene stage cannot use: malformed depth images, camera poses, bins or rack models."""


class SceneError(LoadScenesError):
    """Input a bay's scene cannot be built from: a bay without levels, malformed settings or evidence."""
