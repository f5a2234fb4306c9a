"""A floor plan as store records: the C_W layer, unit and door features, the unit graph."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from services.floor_plan.likelihood import CellClass
from services.floor_plan.mapfile import geojson
from services.floor_plan.pipeline import FloorPlan
from services.floor_plan.world import Rect, World
from shared.store import Feature, GridLayer, TopologyEdge, TopologyNode
from shared.vocabulary import FeatureKind

FLOOR_PLAN_ENCODING = "floor_plan"


def unit_key(unit_id: int) -> str:
    """Feature and topology key of a unit; it stays while the unit only changes shape."""
    return f"u{unit_id}"


def plan_layer(plan: FloorPlan, *, name: str, meta: Mapping[str, Any] | None = None) -> GridLayer:
    """C_W as a uint8 layer (0 free, 1 unknown, 2 wall; meta ``encoding`` = ``floor_plan``), map-aligned."""
    ox, oy = plan.origin_xy_m
    return GridLayer(name, plan.classes_world.astype(np.uint8), plan.resolution_m, ox, oy, {
        "encoding": FLOOR_PLAN_ENCODING, "classes": [c.name.lower() for c in CellClass],
        "k": round(plan.k, 6), "k_units": round(plan.k_units, 6), "clutter": plan.clutter,
        "wall_segments": plan.wall_segments, "slanted_walls": plan.slanted_walls, "exterior": plan.exterior,
        **dict(meta or {}),
    })


def world_meta(world: World) -> dict[str, Any]:
    """The world as JSON for the layer's meta (``world``), so a restarted worker carries on from it."""
    return {"units": [[u, *r] for u, r in sorted(world.units.items())], "doors": [list(d) for d in sorted(world.doors)],
            "next_id": world.next_id}


def world_from_meta(meta: Mapping[str, Any]) -> World | None:
    """The world :func:`world_meta` stored in a layer's meta; None when it is absent or not one."""
    data: Any = meta.get("world", {})
    try:
        units = {int(u): Rect(*(int(v) for v in rest)) for u, *rest in data["units"]}
        doors = {Rect(*(int(v) for v in d)) for d in data["doors"]}
        next_id = int(data["next_id"])
    except (TypeError, KeyError, ValueError):
        return None
    if next_id <= max(units, default=0):
        return None
    return World(units, doors, next_id)


def plan_features(plan: FloorPlan) -> dict[str, list[Feature]]:
    """``unit`` features (polygon, ``label`` = type, ``probability``, ``area_m2``, ``adjacent`` keys, ``rooms``: the
    keys of the rooms it is part of, :func:`~services.floor_plan.rooms.room_keys`), ``door``
    features (segment, the two unit keys, ``width_m``) and ``obstacle`` features (the solid blocks' polygons,
    for the grid decomposition and planners); every kind always present."""
    out: dict[str, list[Feature]] = {FeatureKind.UNIT: [], FeatureKind.DOOR: [], FeatureKind.OBSTACLE: []}
    for item in geojson(plan)["features"]:
        props = item["properties"]
        if props["kind"] == FeatureKind.UNIT:
            out[FeatureKind.UNIT].append(Feature(FeatureKind.UNIT, unit_key(props["id"]), item["geometry"], {
                "label": props["label"], "area_m2": props["area_m2"],
                "adjacent": [unit_key(u) for u in props["adjacent"]], "rooms": props["rooms"],
            }, confidence=props["probability"]))
        elif props["kind"] == FeatureKind.OBSTACLE:
            out[FeatureKind.OBSTACLE].append(Feature(FeatureKind.OBSTACLE, f"o{props['id']}", item["geometry"],
                                                     {"standing": props["standing"]}))
        else:
            a, b = props["units"]
            start = item["geometry"]["coordinates"][0]
            key = f"d{a}-{b}-{start[0]:.2f}-{start[1]:.2f}"
            out[FeatureKind.DOOR].append(Feature(FeatureKind.DOOR, key, item["geometry"], {
                "units": [unit_key(a), unit_key(b)], "width_m": props["width_m"],
            }))
    return out


def plan_topology(plan: FloorPlan) -> tuple[list[TopologyNode], list[TopologyEdge]]:
    """Units as nodes (kind = type, at the centre) and adjacent pairs as edges (``connection`` door or wall)."""
    doors = {frozenset(d.units) for d in plan.doors}
    nodes = []
    for u in plan.units:
        xs = [p[0] for p in u.polygon_xy_m[:4]]
        ys = [p[1] for p in u.polygon_xy_m[:4]]
        nodes.append(TopologyNode(unit_key(u.id), str(u.unit_type), sum(xs) / 4, sum(ys) / 4,
                                  {"feature_kind": FeatureKind.UNIT, "area_m2": round(u.area_m2, 3)}))
    edges = [TopologyEdge(unit_key(a), unit_key(b), {"connection": "door" if frozenset((a, b)) in doors else "wall"})
             for a, b in plan.adjacency]
    return nodes, edges
