"""Blocking and unblocking regions and connections: read the operator's blocks, change them, write them back
as one ``operator`` revision (under :data:`~atlas.navigation.blocks.OPERATOR_LOCK`)."""

from __future__ import annotations

from dataclasses import dataclass

from atlas.cache import RevisionCache
from atlas.errors import ConflictError, InvalidQueryError, NotInMapError
from atlas.navigation.blocks import OPERATOR_LOCK, Block, is_aisle_key, now_iso, region_id, region_pair, write_blocks
from atlas.navigation.graph import NavMap, ResolvedBlock, load_navmap
from shared.store import MapStore, Revision


@dataclass(frozen=True, slots=True)
class Blocked:
    """A block made (or renewed: ``renewed``) on the navigation map ``nav``, stored by ``revision``."""

    block: ResolvedBlock
    nav: NavMap
    revision: Revision
    renewed: bool
    """Whether the same region or connection was blocked already (its block replaced)."""


@dataclass(frozen=True, slots=True)
class Unblocked:
    """The blocks removed from the navigation map ``nav``, the change stored by ``revision``."""

    removed: list[ResolvedBlock]
    nav: NavMap
    revision: Revision


def _existing_region(nav: NavMap, key: str) -> int:
    rid = region_id(key)
    if rid is None or rid not in nav.regions:
        raise NotInMapError(f"the map has no region {key}; see /v1/maps/<map>/topology for its regions")
    return rid


def _alone_on(item: ResolvedBlock, rid: int) -> bool:
    """Whether ``item`` is a block of a region (not of an aisle) that applies to region ``rid`` now."""
    return item.ids == (rid,) and not is_aisle_key(item.block.keys[0])


def _store(store: MapStore, map_id: int, keep: list[ResolvedBlock], added: Block | None, change: str) -> Revision:
    blocks = [item.block for item in keep] + ([added] if added is not None else [])
    return write_blocks(store, map_id, blocks, change=change)


def _block_aisle(store: MapStore, nav: NavMap, map_id: int, aisle: str, *, reason: str | None,
                 by: str | None) -> Blocked:
    if aisle not in nav.aisles:
        raise NotInMapError(f"the map has no aisle {aisle}; aisles are the rack rows' corridor features "
                            "(/v1/maps/<map>/features?kind=corridor)")
    ids = nav.aisle_regions(aisle)
    hubs = [(hub, i) for i in ids if (hub := nav.hub(i)) is not None]
    if not hubs:
        raise ConflictError(f"no drivable region of the decomposition lies in {aisle} yet; block its regions instead")
    biggest = max(hubs, key=lambda item: nav.regions[item[1]].area_m2 or 0.0)[0]
    same = [item for item in nav.blocks if item.block.keys == (aisle,)]
    block = Block((aisle,), biggest[0], biggest[1], reason, now_iso(), by)
    revision = _store(store, map_id, [i for i in nav.blocks if i not in same], block, f"blocked aisle {aisle}")
    return Blocked(ResolvedBlock(block, ids), nav, revision, bool(same))


def block_region(store: MapStore, cache: RevisionCache, map_id: int, region: str, *, reason: str | None,
                 by: str | None) -> Blocked:
    """Close drivable region ``region`` (``r<id>``), or every drivable region of aisle ``region``
    (``aisle-NN``), to routes, for ``reason``, by the key named ``by``.

    Raises
    ------
    NotInMapError
        The map has no such region or aisle.
    InvalidQueryError
        The region is not drivable.
    ConflictError
        The region has no cells, or no drivable region lies in the aisle.
    NavigationError
        The map is not decomposed.
    """
    with OPERATOR_LOCK:
        nav = load_navmap(store, map_id, cache=cache)
        if is_aisle_key(region):
            return _block_aisle(store, nav, map_id, region, reason=reason, by=by)
        rid = _existing_region(nav, region)
        if not nav.regions[rid].drivable:
            raise InvalidQueryError(f"{nav.describe(rid)} is not a drivable region; routes never pass it")
        hub = nav.hub(rid)
        if hub is None:
            raise ConflictError(f"{nav.describe(rid)} has no cells in the segment layer")
        same = [item for item in nav.blocks if item.block.keys == (region,) or _alone_on(item, rid)]
        block = Block((region,), hub[0], hub[1], reason, now_iso(), by)
        revision = _store(store, map_id, [i for i in nav.blocks if i not in same], block, f"blocked region {region}")
    return Blocked(ResolvedBlock(block, (rid,)), nav, revision, bool(same))


def unblock_region(store: MapStore, cache: RevisionCache, map_id: int, region: str) -> Unblocked:
    """Open region or aisle ``region`` again: every block made for its key, and (a region) every block
    that applies to it alone now.

    Raises
    ------
    NotInMapError
        The region is not blocked.
    NavigationError
        The map is not decomposed.
    """
    rid = region_id(region)
    with OPERATOR_LOCK:
        nav = load_navmap(store, map_id, cache=cache)
        gone = [item for item in nav.blocks if item.block.is_region
                and (item.block.keys == (region,) or (rid is not None and _alone_on(item, rid)))]
        if not gone:
            aisles = [item.block.keys[0] for item in nav.blocks
                      if item.block.is_region and item.ids is not None and rid in item.ids]
            raise NotInMapError(f"region {region} is not blocked" + (
                f" itself; it lies in blocked {', '.join(aisles)}: unblock that" if aisles else ""))
        revision = _store(store, map_id, [i for i in nav.blocks if i not in gone], None, f"unblocked region {region}")
    return Unblocked(gone, nav, revision)


def block_connection(store: MapStore, cache: RevisionCache, map_id: int, a: str, b: str, *, reason: str | None,
                     by: str | None) -> Blocked:
    """Close the passage between neighbouring regions ``a`` and ``b`` (either order).

    Raises
    ------
    NotInMapError
        The map lacks a region, or the two are not connected.
    InvalidQueryError
        The regions share no boundary.
    NavigationError
        The map is not decomposed.
    """
    with OPERATOR_LOCK:
        nav = load_navmap(store, map_id, cache=cache)
        ids = tuple(sorted((_existing_region(nav, a), _existing_region(nav, b))))
        if not nav.graph.has_edge(*ids):
            raise NotInMapError(f"regions {a} and {b} are not connected")
        portal = nav.graph.edges[ids]["portal"]
        if portal is None:
            raise InvalidQueryError(f"regions {a} and {b} share no boundary; no vehicle passes between them")
        same = [item for item in nav.blocks if item.ids == ids]
        block = Block(region_pair(nav.key(ids[0]), nav.key(ids[1])), portal.x_m, portal.y_m, reason, now_iso(), by)
        revision = _store(store, map_id, [i for i in nav.blocks if i not in same], block,
                          f"blocked connection {a}-{b}")
    return Blocked(ResolvedBlock(block, ids), nav, revision, bool(same))


def unblock_connection(store: MapStore, cache: RevisionCache, map_id: int, a: str, b: str) -> Unblocked:
    """Open the connection between regions ``a`` and ``b`` (either order) again.

    Raises
    ------
    NotInMapError
        The connection is not blocked.
    NavigationError
        The map is not decomposed.
    """
    keys = region_pair(a, b)
    ids = tuple(sorted(i for i in (region_id(a), region_id(b)) if i is not None))
    with OPERATOR_LOCK:
        nav = load_navmap(store, map_id, cache=cache)
        gone = [item for item in nav.blocks if not item.block.is_region
                and (item.ids == ids or (item.ids is None and item.block.keys == keys))]
        if not gone:
            raise NotInMapError(f"the connection {a}-{b} is not blocked")
        revision = _store(store, map_id, [i for i in nav.blocks if i not in gone], None,
                          f"unblocked connection {a}-{b}")
    return Unblocked(gone, nav, revision)
