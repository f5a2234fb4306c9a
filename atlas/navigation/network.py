"""The waypoint network of a map, as fleet-manager formats want it (LIF, Open-RMF nav graphs).

Nodes: a hub in every junction, room and open area (a free cell near its middle), a node on every
portal between two usable regions, an access node where bins are served (bins at several levels
of one bay share their access pose, hence one node) and a node at each dock, gate and charger.
Edges stay inside one region: along a corridor its nodes are chained in order along the
corridor's long axis; in the other regions every node is joined to the hub. An edge whose straight
line would leave the free cells goes round the obstacle through ``via`` nodes (grid search); one
that cannot is left out. Blocked regions and connections are left out altogether; bins and places
more than :data:`~atlas.navigation.graph.LOCATE_TOLERANCE_M` off a usable region are listed in
``left_out``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from atlas.navigation.ends import geometry_centre, place_pose
from atlas.navigation.graph import NavMap
from atlas.navigation.grid import BoolGrid, Point, grid_path, grown, segment_clear
from atlas.navigation.routes import usable_graph
from shared.store import Feature
from shared.vocabulary import FeatureKind

NodeKind = Literal["hub", "portal", "access", "place", "via"]


@dataclass(frozen=True, slots=True)
class NetNode:
    """A network node in region ``region`` (key); ``bins`` served from an access node, ``place`` (kind, key)."""

    id: str
    x_m: float
    y_m: float
    kind: NodeKind
    region: str
    yaw_rad: float | None = None
    bins: tuple[str, ...] = ()
    place: tuple[str, str] | None = None


@dataclass(frozen=True, slots=True)
class NetEdge:
    """An undirected leg between nodes ``a`` and ``b`` inside region ``region`` of kind ``region_kind``."""

    id: str
    a: str
    b: str
    region: str
    region_kind: str
    length_m: float


@dataclass(frozen=True, slots=True)
class Station:
    """Where a vehicle interacts with something: a bin or a place, served from node ``node``."""

    id: str
    kind: str
    key: str
    node: str
    x_m: float
    y_m: float
    yaw_rad: float | None
    height_m: float | None = None
    name: str | None = None


@dataclass
class Network:
    nodes: list[NetNode] = field(default_factory=list)
    edges: list[NetEdge] = field(default_factory=list)
    stations: list[Station] = field(default_factory=list)
    left_out: list[str] = field(default_factory=list)
    """``<kind>/<key>`` of bins and places with no usable region within reach."""


def _number(value: object) -> float | None:
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return None


def _access(feature: Feature) -> tuple[float, float, float | None] | None:
    pose = feature.properties.get("access_pose")
    if not isinstance(pose, list | tuple) or len(pose) != 3:
        return None
    values = [_number(v) for v in pose]
    if values[0] is None or values[1] is None:
        return None
    return values[0], values[1], values[2]


class _Builder:
    def __init__(self, nav: NavMap) -> None:
        self.nav = nav
        self.regions = usable_graph(nav)
        self.mask: BoolGrid = nav.mask(set(self.regions.nodes))
        self.net = Network()
        self.stops: dict[int, list[NetNode]] = {rid: [] for rid in self.regions.nodes}
        self.by_id: dict[str, NetNode] = {}

    def add(self, node: NetNode, *regions: int) -> NetNode:
        if node.id not in self.by_id:
            self.by_id[node.id] = node
            self.net.nodes.append(node)
        for rid in regions:
            self.stops[rid].append(self.by_id[node.id])
        return self.by_id[node.id]

    def locate(self, x: float, y: float) -> tuple[int, Point] | None:
        found = self.nav.locate(x, y)
        return found if found is not None and found[0] in self.regions else None

    def structure(self) -> None:
        nav = self.nav
        for rid in sorted(self.regions.nodes):
            region = nav.regions[rid]
            hub = nav.hub(rid)
            if region.kind != FeatureKind.CORRIDOR and hub is not None:
                self.add(NetNode(f"{region.kind}-{region.key}", *hub, "hub", region.key), rid)
        for a, b, data in sorted(self.regions.edges(data=True)):
            portal = data["portal"]
            self.add(NetNode(f"portal-{nav.key(a)}-{nav.key(b)}", portal.x_m, portal.y_m, "portal", nav.key(a)),
                     a, b)

    def bins(self, bins: Sequence[Feature]) -> None:
        groups: dict[tuple[int, int, int], list[tuple[Feature, float | None]]] = {}
        for feature in sorted(bins, key=lambda f: f.key):
            pose = _access(feature)
            found = None if pose is None else self.locate(pose[0], pose[1])
            if pose is None or found is None:
                self.net.left_out.append(f"bin/{feature.key}")
                continue
            rid, point = found
            groups.setdefault((rid, round(point[0] * 100), round(point[1] * 100)), []).append((feature, pose[2]))
        for (rid, cx, cy), members in groups.items():
            ids = tuple(f.key for f, _ in members)
            node = self.add(NetNode(f"access-{ids[0]}", cx / 100, cy / 100, "access", self.nav.key(rid),
                                    members[0][1], ids), rid)
            for feature, yaw in members:
                x, y = _bin_centre(feature)
                self.net.stations.append(Station(feature.key, FeatureKind.BIN.value, feature.key, node.id, x, y, yaw,
                                                 _number(feature.properties.get("z_m"))))

    def places(self, places: Sequence[Feature]) -> None:
        for feature in sorted(places, key=lambda f: (f.kind, f.key)):
            x, y, yaw = place_pose(feature)
            found = self.locate(x, y)
            if found is None:
                self.net.left_out.append(f"{feature.kind}/{feature.key}")
                continue
            rid, point = found
            node = self.add(NetNode(f"{feature.kind}-{feature.key}", *point, "place", self.nav.key(rid), yaw,
                                    place=(feature.kind, feature.key)), rid)
            name = feature.properties.get("name")
            cx, cy = geometry_centre(feature.geometry)
            self.net.stations.append(Station(f"{feature.kind}-{feature.key}", feature.kind, feature.key, node.id,
                                             cx, cy, yaw, None, name if isinstance(name, str) else None))

    def legs(self) -> None:
        for rid, stops in self.stops.items():
            region = self.nav.regions[rid]
            if region.kind == FeatureKind.CORRIDOR:
                pairs = list(itertools.pairwise(self._along_axis(rid, stops)))
            else:
                hub = next((s for s in stops if s.kind == "hub"), None)
                pairs = [] if hub is None else [(hub, s) for s in stops if s is not hub]
            for n, (a, b) in enumerate(pairs):
                self._leg(rid, f"{region.key}-{n}", a, b)

    def _along_axis(self, rid: int, stops: list[NetNode]) -> list[NetNode]:
        if len(stops) < 2:
            return stops
        slices = self.nav.grid.slices[rid]
        rows, cols = np.nonzero(self.nav.grid.segments[slices] == rid)
        cells = np.column_stack([cols, rows]).astype(float)
        cells -= cells.mean(axis=0)
        _, vectors = np.linalg.eigh(cells.T @ cells)
        axis = vectors[:, -1]
        return sorted(stops, key=lambda s: (float(axis[0] * s.x_m + axis[1] * s.y_m), s.id))

    def _leg(self, rid: int, name: str, a: NetNode, b: NetNode) -> None:
        p, q = (a.x_m, a.y_m), (b.x_m, b.y_m)
        points: list[Point] | None = [p, q]
        if not segment_clear(self.mask, self.nav.frame, p, q):
            slices = grown(self.nav.grid.slices[rid], self.nav.frame.shape, 2)
            points = grid_path(self.mask, self.nav.frame, p, q, within=slices)
        if points is None:
            return
        region = self.nav.regions[rid]
        chain = [a]
        for k, xy in enumerate(points[1:-1]):
            chain.append(self.add(NetNode(f"via-{name}-{k}", *xy, "via", region.key)))
        chain.append(b)
        for k, (u, v) in enumerate(itertools.pairwise(chain)):
            self.net.edges.append(NetEdge(name if len(chain) == 2 else f"{name}.{k}", u.id, v.id, region.key,
                                          region.kind, math.dist((u.x_m, u.y_m), (v.x_m, v.y_m))))


def _bin_centre(feature: Feature) -> Point:
    centre = feature.properties.get("centre")
    if isinstance(centre, list | tuple) and len(centre) == 2:
        x, y = _number(centre[0]), _number(centre[1])
        if x is not None and y is not None:
            return x, y
    return geometry_centre(feature.geometry)


def waypoint_network(nav: NavMap, *, bins: Sequence[Feature] = (), places: Sequence[Feature] = ()) -> Network:
    """The waypoint network of ``nav`` with access nodes for ``bins`` and nodes for ``places`` (docks,
    gates, chargers), and a station per bin and place."""
    builder = _Builder(nav)
    builder.structure()
    builder.bins(bins)
    builder.places(places)
    builder.legs()
    return builder.net
