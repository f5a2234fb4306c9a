"""The navigation map: regions of the grid decomposition, their connections and portals, free cells, blocks.

:func:`region_grid` does the per-layer work (free cells, region extents, portals) and is worth
caching per layer version; :func:`build_navmap` joins it with the stored topology and the
operator's blocks, which is cheap. :func:`load_navmap` reads everything from the store.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import networkx as nx
import numpy as np
import numpy.typing as npt

from atlas.cache import RevisionCache
from atlas.grids import DRIVABLE_PLACES, cached_layer
from atlas.navigation.blocks import (
    AISLE_KEY_PATTERN,
    Block,
    blocks_of,
    is_aisle_key,
    is_block_edge,
    is_block_node,
    region_id,
)
from atlas.navigation.errors import NavigationUnavailableError
from atlas.navigation.grid import BoolGrid, Frame, Point, free_cells, nearest_cell, polygon_cells, region_slices
from atlas.navigation.portals import Portal, find_portals
from shared.store import GridLayer, MapStore, TopologyEdge, TopologyNode
from shared.vocabulary import FeatureKind, LayerName

SEGMENT_LAYER = LayerName.PLACE_SEGMENTS
OCCUPANCY_LAYER = LayerName.OCCUPANCY
RACK_KIND = FeatureKind.BIN
"""Features whose footprints are racks, never driven through (the pillar stage's pallet cells)."""
ROUTE_CONNECTIONS = frozenset({"connected", "door"})
"""Connections a vehicle drives through (not ``storage_access`` nor ``disconnected``)."""
AISLE_SHARE = 0.5
"""A region lies in an aisle (and a block of the aisle applies to it) when this share of its cells is inside the
aisle's outline."""
LOCATE_TOLERANCE_M = 1.0
"""How far a point (a bin's access pose, a dock) may lie off a drivable region and still be placed in it."""


@dataclass(frozen=True)
class RegionGrid:
    """The segment layer with its free cells (from the occupancy layer), region extents and portals."""

    frame: Frame
    segments: npt.NDArray[np.int32]
    free: BoolGrid
    slices: dict[int, tuple[slice, slice]]
    portals: dict[tuple[int, int], Portal]
    segments_revision: int
    occupancy_revision: int | None


def region_grid(segments: GridLayer, occupancy: GridLayer | None, *, segments_revision: int,
                occupancy_revision: int | None, racks: Sequence[npt.NDArray[np.float64]] = ()) -> RegionGrid:
    """A :class:`RegionGrid` of a segment layer; without an occupancy layer every region cell counts as free.

    ``racks`` are footprints (K, 2) in map metres (the bins' pallet cells) that are never free: a 2-D lidar
    sees under an empty rack bay, but no vehicle drives through one.
    """
    frame = Frame.of(segments)
    ids = segments.data.astype(np.int32)
    free = free_cells(occupancy, frame) if occupancy is not None else ids > 0
    if racks:
        free = free & ~polygon_cells(racks, frame)
    return RegionGrid(frame, ids, free, region_slices(ids), find_portals(ids, frame), segments_revision,
                      occupancy_revision)


@dataclass(frozen=True)
class Region:
    """A region of the decomposition: id, key (``r<id>``), kind (its label: corridor, storage, ...), centroid, and
    the aisle it is (``aisle-03``) where the racks are known."""

    id: int
    key: str
    kind: str
    x_m: float | None
    y_m: float | None
    area_m2: float | None
    aisle: str | None = None

    @property
    def drivable(self) -> bool:
        return self.kind in DRIVABLE_PLACES


@dataclass(frozen=True)
class ResolvedBlock:
    """A stored block and the region ids it applies to now (a region block: its region, or every region of its
    aisle; a connection block: the connected pair); None when it no longer matches anything (the region or
    passage at its point is gone)."""

    block: Block
    ids: tuple[int, ...] | None


@dataclass
class NavMap:
    """Everything routes, the topology view and the exports need, at one revision.

    ``graph`` has a node per region id (attributes ``region``: :class:`Region`, ``blocked``) and an
    edge per stored connection (``connection``, ``portal``: :class:`Portal` or None when the two
    regions share no boundary, ``blocked``).
    """

    grid: RegionGrid
    regions: dict[int, Region]
    graph: nx.Graph
    blocks: list[ResolvedBlock]
    revision: int | None = None
    aisles: dict[str, list[npt.NDArray[np.float64]]] = field(default_factory=dict)
    """Outlines (K, 2) in map metres of the aisles (``aisle-NN`` corridor features), by key."""
    _hubs: dict[int, Point | None] = field(default_factory=dict)

    @property
    def frame(self) -> Frame:
        return self.grid.frame

    @cached_property
    def blocked_ids(self) -> frozenset[int]:
        return frozenset(i for b in self.blocks if b.ids is not None and b.block.is_region for i in b.ids)

    @cached_property
    def blocked_pairs(self) -> frozenset[tuple[int, int]]:
        return frozenset((b.ids[0], b.ids[1]) for b in self.blocks if b.ids is not None and not b.block.is_region)

    @cached_property
    def drivable_ids(self) -> frozenset[int]:
        return frozenset(i for i, region in self.regions.items() if region.drivable and i in self.grid.slices)

    def mask(self, ids: Collection[int]) -> BoolGrid:
        """Free cells of the regions ``ids``."""
        segments = self.grid.segments
        table = np.zeros(int(segments.max(initial=0)) + 1, dtype=bool)
        chosen = [i for i in ids if 0 < i < table.size]
        table[chosen] = True
        return self.grid.free & table[segments]

    @cached_property
    def drivable_mask(self) -> BoolGrid:
        return self.mask(self.drivable_ids)

    def locate(self, x_m: float, y_m: float, *, tolerance_m: float = LOCATE_TOLERANCE_M
               ) -> tuple[int, Point] | None:
        """The drivable region at (x, y), or the nearest free drivable cell's within ``tolerance_m``: (id, point).

        The point is (x, y) itself when its cell is free and drivable, else that nearest cell's centre.
        Blocks are not looked at (a point in a blocked corridor is still in that corridor).
        """
        cell = nearest_cell(self.drivable_mask, self.frame, x_m, y_m, tolerance_m=tolerance_m)
        if cell is None:
            return None
        rid = int(self.grid.segments[cell])
        if self.frame.cell(x_m, y_m) == cell:
            return rid, (x_m, y_m)
        return rid, self.frame.centre(*cell)

    def hub(self, rid: int) -> Point | None:
        """A free cell centre of region ``rid`` nearest the mean of its cells (inside it even when concave)."""
        if rid not in self._hubs:
            self._hubs[rid] = self._hub(rid)
        return self._hubs[rid]

    def _hub(self, rid: int) -> Point | None:
        slices = self.grid.slices.get(rid)
        if slices is None:
            return None
        inside = self.grid.segments[slices] == rid
        usable = inside & self.grid.free[slices]
        rows, cols = np.nonzero(usable if usable.any() else inside)
        far = (rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2
        best = int(np.argmin(far))
        return self.frame.centre(float(rows[best] + slices[0].start), float(cols[best] + slices[1].start))

    def aisle_regions(self, key: str) -> tuple[int, ...]:
        """Drivable regions lying in aisle ``key`` (:data:`AISLE_SHARE` of their cells in its outline), by id."""
        return _in_outline(self.grid, self.aisles.get(key, []), self.drivable_ids)

    def key(self, rid: int) -> str:
        region = self.regions.get(rid)
        return region.key if region is not None else f"r{rid}"

    def describe(self, rid: int) -> str:
        """``r12 (corridor)``."""
        region = self.regions.get(rid)
        return f"r{rid}" if region is None else f"{region.key} ({region.kind})"


def _in_outline(grid: RegionGrid, rings: list[npt.NDArray[np.float64]], ids: Collection[int]) -> tuple[int, ...]:
    if not rings or not ids:
        return ()
    inside = polygon_cells(rings, grid.frame)
    n = int(grid.segments.max(initial=0)) + 1
    total = np.bincount(grid.segments.ravel(), minlength=n)
    held = np.bincount(grid.segments[inside], minlength=n)
    return tuple(sorted(i for i in ids if 0 < i < n and held[i] >= AISLE_SHARE * total[i] > 0))


def _resolve(block: Block, nav: NavMap, *, tolerance_m: float) -> tuple[int, ...] | None:
    grid, graph = nav.grid, nav.graph
    if block.is_region:
        own = region_id(block.keys[0])
        if own is not None and own in nav.regions and own in grid.slices:
            return (own,)
        if is_aisle_key(block.keys[0]) and (inside := nav.aisle_regions(block.keys[0])):
            return inside
        cell = nearest_cell(grid.segments > 0, grid.frame, block.x_m, block.y_m, tolerance_m=tolerance_m)
        return None if cell is None else (int(grid.segments[cell]),)
    same = tuple(sorted(i for i in (region_id(k) for k in block.keys) if i is not None))
    candidates = [(math.dist((p.x_m, p.y_m), (block.x_m, block.y_m)), (p.a, p.b) != same, (p.a, p.b))
                  for p in grid.portals.values() if graph.has_edge(p.a, p.b)]
    near = [c for c in candidates if c[0] <= tolerance_m]
    if not near:
        return None
    return min(near, key=lambda c: (c[1], c[0]))[2]


def build_navmap(grid: RegionGrid, nodes: Sequence[TopologyNode], edges: Sequence[TopologyEdge], *,
                 revision: int | None = None, tolerance_m: float = LOCATE_TOLERANCE_M,
                 aisles: Mapping[str, list[npt.NDArray[np.float64]]] | None = None) -> NavMap:
    """Join a :class:`RegionGrid` with a map's topology records (the decomposition's regions and
    connections, the operator's blocks) and the aisles' outlines (by key, for blocks of aisles).

    Nodes whose key is not ``r<id>`` and blocks' records are not regions; an edge between two
    regions gets the portal of their shared boundary, if any.
    """
    regions: dict[int, Region] = {}
    for node in nodes:
        rid = region_id(node.key)
        if rid is None or is_block_node(node):
            continue
        area, aisle = node.attributes.get("area_m2"), node.attributes.get("aisle")
        regions[rid] = Region(rid, node.key, node.kind, node.x_m, node.y_m,
                              float(area) if isinstance(area, int | float) else None,
                              aisle if isinstance(aisle, str) else None)
    graph = nx.Graph()
    for rid, region in regions.items():
        graph.add_node(rid, region=region, blocked=False)
    for edge in edges:
        a, b = region_id(edge.source), region_id(edge.target)
        if is_block_edge(edge) or a is None or b is None or a not in regions or b not in regions or a == b:
            continue
        pair = (min(a, b), max(a, b))
        graph.add_edge(*pair, connection=str(edge.attributes.get("connection", "")), portal=grid.portals.get(pair),
                       blocked=False)
    nav = NavMap(grid, regions, graph, [], revision, aisles=dict(aisles or {}))
    nav.blocks = [ResolvedBlock(b, _resolve(b, nav, tolerance_m=tolerance_m)) for b in blocks_of(nodes, edges)]
    for item in nav.blocks:
        if item.ids is not None and item.block.is_region:
            for rid in item.ids:
                if rid in graph:
                    graph.nodes[rid]["blocked"] = True
        elif item.ids is not None:
            graph.edges[item.ids]["blocked"] = True
    return nav


def load_navmap(store: MapStore, map_id: int, *, revision: int | None = None,
                cache: RevisionCache | None = None) -> NavMap:
    """The :class:`NavMap` of a map as of ``revision`` (default: its newest revision, read once so the layers
    and the topology all come from the same moment).

    Raises
    ------
    NavigationUnavailableError
        The map has no ``place_segments`` layer (the grid decomposition has not run) at that revision.
    """
    cache = cache if cache is not None else RevisionCache(size=4)
    latest = store.latest_revision(map_id)
    at = revision if revision is not None or latest is None else latest.id
    segments_revision = store.layer_revision(map_id, SEGMENT_LAYER, revision=at)
    segments = None if segments_revision is None else cached_layer(store, cache, map_id, SEGMENT_LAYER,
                                                                   segments_revision)
    if segments is None or segments_revision is None:
        when = "yet" if revision is None else f"at revision {revision}"
        raise NavigationUnavailableError(
            f"the map has no {SEGMENT_LAYER} layer {when}: the grid_decomposition stage has not decomposed its "
            "occupancy grid, so there are no regions to navigate")
    occupancy_revision = store.layer_revision(map_id, OCCUPANCY_LAYER, revision=at)
    occupancy = None if occupancy_revision is None else cached_layer(store, cache, map_id, OCCUPANCY_LAYER,
                                                                     occupancy_revision)

    bins = store.features(map_id, kinds=[RACK_KIND], revision=at)
    racks = [np.asarray(b.feature.geometry["coordinates"][0], dtype=np.float64) for b in bins
             if b.feature.geometry.get("type") == "Polygon"]
    racks_revision = max((b.revision_id for b in bins), default=None)

    def build() -> RegionGrid:
        return region_grid(segments, occupancy, segments_revision=segments_revision,
                           occupancy_revision=occupancy_revision, racks=racks)

    grid = cache.get(("region_grid", store.url, map_id, segments_revision, occupancy_revision, racks_revision),
                     build)
    nodes, edges = store.topology(map_id, revision=at)
    aisles = {c.feature.key: _outer_rings(c.feature.geometry)
              for c in store.features(map_id, kinds=[FeatureKind.CORRIDOR], revision=at)
              if re.match(AISLE_KEY_PATTERN, c.feature.key)}
    return build_navmap(grid, nodes, edges, revision=at, aisles=aisles)


def _outer_rings(geometry: Mapping[str, Any]) -> list[npt.NDArray[np.float64]]:
    polygons = {"Polygon": [geometry.get("coordinates")], "MultiPolygon": geometry.get("coordinates")}.get(
        str(geometry.get("type")), [])
    return [np.asarray(polygon[0], dtype=np.float64).reshape(-1, 2) for polygon in polygons or [] if polygon]
