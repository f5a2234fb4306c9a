"""The load-scene service's error type."""

from __future__ import annotations


class SceneError(ValueError):
    """Input a bay's scene cannot be built from: a bay without levels, malformed settings or evidence."""
