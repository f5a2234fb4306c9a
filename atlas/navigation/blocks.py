"""Blocked regions and connections: operator input kept in the map store as the ``operator`` stage's topology.

A blocked region is a topology node of kind ``blocked``; a blocked connection is a topology edge
whose attributes have ``kind: blocked``. Each remembers a point (inside the region, or the portal
of the connection) besides the region keys it was made for. Region keys are stable while the place is
the same (the grid decomposition carries them over by overlap), but a place can vanish or merge: at read
time a block applies to the region with its key, else whatever region (or connection) now lies at its
point. A block of an aisle (``aisle-03``, the pillar stage's corridor feature) applies to every drivable
region lying mostly in the aisle's outline at read time. Writing replaces the operator stage's whole graph,
so callers read the current set, change it and write it back (:func:`write_blocks`).
"""

from __future__ import annotations

import datetime as dt
import math
import re
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from shared.store import MapStore, Revision, RevisionWrite, TopologyEdge, TopologyNode

OPERATOR_STAGE = "operator"
"""Stage name of everything people set through the API (blocked regions and connections, places)."""
OPERATOR_LOCK = threading.Lock()
"""Serialises this process's read-modify-write of the operator stage's records (blocks, places): each write
replaces the stage's whole set of a kind, so two at once would lose one. Several API processes writing
at the same moment can still race; one operator at a time is the expected use."""
BLOCKED_KIND = "blocked"
REGION_KEY_PATTERN = r"^r[0-9]{1,9}$"
"""A region key as the grid decomposition writes it: ``r`` and the region id."""
AISLE_KEY_PATTERN = r"^aisle-[0-9]{1,9}$"
"""An aisle's key as the pillar stage writes its ``corridor`` feature: ``aisle-03``."""
BLOCKABLE_KEY_PATTERN = r"^(r[0-9]{1,9}|aisle-[0-9]{1,9})$"
"""What a region block may name: a region, or an aisle (every drivable region lying in it)."""
_REGION_KEY = re.compile(REGION_KEY_PATTERN)
_AISLE_KEY = re.compile(AISLE_KEY_PATTERN)


def region_id(key: str) -> int | None:
    """The region id of key ``r<id>``, or None for any other key."""
    return int(key[1:]) if _REGION_KEY.match(key) else None


def is_aisle_key(key: str) -> bool:
    """Whether ``key`` names an aisle (``aisle-NN``)."""
    return _AISLE_KEY.match(key) is not None


def region_pair(a: str, b: str) -> tuple[str, str]:
    """The two region keys in a fixed order (by id), so a connection has one name."""
    return (a, b) if (region_id(a) or 0, a) <= (region_id(b) or 0, b) else (b, a)


@dataclass(frozen=True, slots=True)
class Block:
    """A region or an aisle (one key) or a connection (two keys, :func:`region_pair` order) an operator closed.

    ``x_m``, ``y_m`` is a point inside the region, or the portal of the connection, when it was
    blocked (map metres); ``blocked_at`` an ISO 8601 UTC time; ``blocked_by`` the name of the API
    key that blocked it, if any.
    """

    keys: tuple[str, ...]
    x_m: float
    y_m: float
    reason: str | None = None
    blocked_at: str = ""
    blocked_by: str | None = None

    @property
    def is_region(self) -> bool:
        return len(self.keys) == 1

    def attributes(self) -> dict[str, Any]:
        return {"kind": BLOCKED_KIND, "blocked": True, "x_m": self.x_m, "y_m": self.y_m, "reason": self.reason,
                "blocked_at": self.blocked_at, "blocked_by": self.blocked_by}


def now_iso() -> str:
    """The current UTC time as ISO 8601 with a ``Z``."""
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


def _number(value: Any) -> float | None:
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return None


def _text(value: Any) -> str | None:
    return value if isinstance(value, str) else None


def is_block_node(node: TopologyNode) -> bool:
    return node.kind == BLOCKED_KIND


def is_block_edge(edge: TopologyEdge) -> bool:
    return edge.attributes.get("kind") == BLOCKED_KIND


def blocks_of(nodes: Sequence[TopologyNode], edges: Sequence[TopologyEdge]) -> list[Block]:
    """The blocks among a map's topology records (the operator's), in stored order."""
    found: list[Block] = []
    for node in nodes:
        if is_block_node(node) and node.x_m is not None and node.y_m is not None:
            found.append(_block((node.key,), node.x_m, node.y_m, node.attributes))
    for edge in edges:
        x, y = _number(edge.attributes.get("x_m")), _number(edge.attributes.get("y_m"))
        if is_block_edge(edge) and x is not None and y is not None:
            found.append(_block(region_pair(edge.source, edge.target), x, y, edge.attributes))
    return found


def _block(keys: tuple[str, ...], x: float, y: float, attributes: Mapping[str, Any]) -> Block:
    return Block(keys, float(x), float(y), _text(attributes.get("reason")), _text(attributes.get("blocked_at")) or "",
                 _text(attributes.get("blocked_by")))


def read_blocks(store: MapStore, map_id: int, *, revision: int | None = None) -> list[Block]:
    """The blocks live at ``revision`` (default: now)."""
    return blocks_of(*store.topology(map_id, revision=revision))


def write_blocks(store: MapStore, map_id: int, blocks: Sequence[Block], *, change: str) -> Revision:
    """Store ``blocks`` as the operator's complete set, one revision; ``change`` says what changed (summary)."""
    nodes = [TopologyNode(b.keys[0], BLOCKED_KIND, b.x_m, b.y_m, b.attributes()) for b in blocks if b.is_region]
    edges = [TopologyEdge(b.keys[0], b.keys[1], b.attributes()) for b in blocks if not b.is_region]
    return store.write_revision(map_id, RevisionWrite(
        OPERATOR_STAGE, topology=(nodes, edges),
        summary={"operator": change, "blocked_regions": len(nodes), "blocked_connections": len(edges)},
    ))
