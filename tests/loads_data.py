"""A small racked map for the bin-occupancy tests: two bays of two levels, their bins, and what the robots saw.

The records are hand-built inputs of the store writer (what the load-scene stage would give it), not mocks.
"""

from __future__ import annotations

from shared.loads import BinOccupancy, Flag, ObjectKind, Occupancy, Relation, SceneEdge, SceneGraph, SceneNode
from shared.store import Feature, MapStore, RevisionWrite

SEEN_NS = 1_764_126_000_000_000_000
"""2025-11-26T03:00:00Z, when the robots last saw the bays, ns since the epoch."""
BAY_1, BAY_2 = "r0-001/1", "r0-001/2"
BINS = {"01-001-01": (1.0, 1.0), "01-001-02": (1.0, 1.0), "01-002-01": (3.0, 1.0), "01-002-02": (3.0, 1.0),
        "01-003-01": (5.0, 1.0)}
"""Bin ids and centres (x, y), metres; the two levels of a bay share a centre."""


def write_bins(store: MapStore, map_name: str = "site") -> int:
    """Store :data:`BINS` as the pillar stage would; the revision id."""
    map_id = store.ensure_map(map_name).id
    features = [Feature("bin", key, {"type": "Point", "coordinates": list(xy)},
                        {"id": key, "aisle": 1, "bay": int(key[3:6]), "level": int(key[-2:]) - 1, "centre": list(xy)},
                        0.9) for key, xy in BINS.items()]
    return store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": features})).id


def _box(node_id: str, kind: ObjectKind, x: float, z: float, height: float, level: int,
         flags: frozenset[Flag] = frozenset()) -> SceneNode:
    return SceneNode(node_id, kind, (x, 1.0, z), (1.2, 0.8, height), 0.0, level, flags, 0.95)


def bay_1_scene() -> SceneGraph:
    """Bay 1: level 0 a pallet with a load leaning on a neighbour; level 1 (beam at 1.5 m) a ghost pallet."""
    nodes = (
        _box("p1", ObjectKind.PALLET, 1.0, 0.07, 0.14, 0),
        _box("l1", ObjectKind.LOAD, 1.0, 0.6, 0.9, 0),
        _box("l2", ObjectKind.LOAD, 1.3, 0.6, 0.9, 0),
        _box("b1", ObjectKind.BEAM, 1.0, 1.44, 0.12, 1),
        _box("g1", ObjectKind.PALLET, 1.0, 1.57, 0.14, 1, frozenset({Flag.FALSE_ESTIMATE})),
    )
    edges = (SceneEdge("p1", "l1", Relation.SUPPORTS, 0.99), SceneEdge("p1", "l2", Relation.SUPPORTS, 0.9),
             SceneEdge("l1", "l2", Relation.UNSTABLE_CONTACT, 0.8))
    return SceneGraph(BAY_1, nodes, edges, SEEN_NS, iterations=120)


def bay_2_scene() -> SceneGraph:
    """Bay 2: level 0 a pallet inferred behind a gap (hidden), level 1 empty."""
    nodes = (_box("p3", ObjectKind.PALLET, 3.0, 0.07, 0.14, 0, frozenset({Flag.HIDDEN_BELOW})),
             _box("b2", ObjectKind.BEAM, 3.0, 1.44, 0.12, 1))
    return SceneGraph(BAY_2, nodes, (), SEEN_NS, iterations=80)


def seen(bin_id: str, state: Occupancy, *, views: int, objects: tuple[str, ...] = (), bay: str | None = None,
         confidence: float = 0.97, hidden: bool = False) -> BinOccupancy:
    """A bin state as the stage gives it, last seen at :data:`SEEN_NS`."""
    return BinOccupancy(bin_id, state, confidence, SEEN_NS if views else None, objects, views,
                        stable=None if state != Occupancy.OCCUPIED else not objects[1:], hidden=hidden, bay=bay)


def first_survey() -> list[BinOccupancy]:
    """01-001-01 occupied (3 views), 01-001-02 empty (2 views, its ghost pallet rejected), 01-002-01 occupied by a
    hidden pallet (2 views), 01-002-02 empty but seen once; 01-003-01 never seen (no state)."""
    return [seen("01-001-01", Occupancy.OCCUPIED, views=3, objects=("p1", "l1", "l2"), bay=BAY_1),
            seen("01-001-02", Occupancy.EMPTY, views=2, bay=BAY_1),
            seen("01-002-01", Occupancy.OCCUPIED, views=2, objects=("p3",), bay=BAY_2, hidden=True),
            seen("01-002-02", Occupancy.EMPTY, views=1, bay=BAY_2)]
