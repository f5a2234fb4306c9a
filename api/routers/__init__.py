"""One router per resource."""

from api.routers import features, health, layers, maps

__all__ = ["features", "health", "layers", "maps"]
