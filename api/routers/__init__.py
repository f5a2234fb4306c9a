"""One router per resource."""

from api.routers import (
    bins,
    blocks,
    events,
    exports,
    features,
    health,
    history,
    keys,
    layers,
    layout,
    maps,
    places,
    routes,
    semantics,
    topology,
    wms,
)

__all__ = [
    "bins",
    "blocks",
    "events",
    "exports",
    "features",
    "health",
    "history",
    "keys",
    "layers",
    "layout",
    "maps",
    "places",
    "routes",
    "semantics",
    "topology",
    "wms",
]
