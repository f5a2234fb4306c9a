"""One router per resource."""

from api.routers import bins, events, features, health, keys, layers, maps

__all__ = ["bins", "events", "features", "health", "keys", "layers", "maps"]
