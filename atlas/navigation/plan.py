"""A drivable route between two ends a client names (``bin:<WMS id>``, ``dock:G1``, ``point:x,y``), with the
regions and corridors it passes."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from atlas.bins import bin_index, corridors_along
from atlas.cache import RevisionCache
from atlas.errors import InvalidQueryError
from atlas.navigation.blocks import region_id
from atlas.navigation.ends import End, Located, locate_end, parse_end
from atlas.navigation.graph import NavMap, load_navmap
from atlas.navigation.routes import Route, plan_route
from atlas.reconcile import WmsMatching
from shared.store import MapStore
from shared.vocabulary import FeatureKind

MAX_AVOID = 100
"""Most regions a route may be told to avoid."""


@dataclass(frozen=True, slots=True)
class PlannedRoute:
    """A route from ``start`` to ``goal`` on ``nav``, and the keys of the corridor features it runs through."""

    start: Located
    goal: Located
    route: Route
    nav: NavMap
    corridors: list[str]
    """Aisles and decomposition corridors, in the order the route enters them."""


def avoided_regions(nav: NavMap, keys: Sequence[str] | None) -> set[int]:
    """Ids of the regions ``keys`` (``r<id>``) name.

    Raises
    ------
    InvalidQueryError
        More than :data:`MAX_AVOID` keys, a key that is not a region key, or a region the map lacks.
    """
    if not keys:
        return set()
    if len(keys) > MAX_AVOID:
        raise InvalidQueryError(f"at most {MAX_AVOID} regions to avoid")
    ids = set()
    for key in keys:
        rid = region_id(key)
        if rid is None:
            raise InvalidQueryError(f"avoid={key!r} is not a region key; region keys look like r17")
        if rid not in nav.regions:
            raise InvalidQueryError(f"avoid={key}: the map has no region {key}")
        ids.add(rid)
    return ids


def _detected_bin(end: End, matching: WmsMatching | None) -> End:
    """A ``bin:`` end named by the WMS's own id, as Aisle's id of the matched bin."""
    if end.kind != FeatureKind.BIN or end.key is None or matching is None:
        return end
    detected = matching.detected_of(end.key)
    return end if detected is None else End(end.text, end.kind, detected, end.xy)


def route_between(store: MapStore, cache: RevisionCache, map_id: int, *, start: str, goal: str,
                  avoid: Sequence[str] | None, revision: int | None) -> PlannedRoute:
    """The shortest drivable route from end ``start`` to end ``goal`` as of ``revision`` (default: now), never
    through blocked regions and connections nor the regions ``avoid`` names.

    Raises
    ------
    NavigationError
        An end badly written (:class:`EndSyntaxError`) or naming nothing (:class:`UnknownEndError`), no
        regions yet, or no drivable route.
    InvalidQueryError
        A bad ``avoid``.
    """
    index = bin_index(store, cache, map_id, revision)
    ends = [_detected_bin(parse_end(text), index.matching) for text in (start, goal)]
    first, last = (locate_end(store, map_id, end, revision=revision) for end in ends)
    nav = load_navmap(store, map_id, revision=revision, cache=cache)
    route = plan_route(nav, (first.x_m, first.y_m), (last.x_m, last.y_m), avoid=avoided_regions(nav, avoid))
    corridors = corridors_along(index.corridors, [(w.x_m, w.y_m) for w in route.waypoints])
    return PlannedRoute(first, last, route, nav, corridors)
