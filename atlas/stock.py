"""What stands in the racks against what the WMS books: a bin's bay scene, the WMS stock list, and discrepancies.

The load-scene stage stores each bin's occupancy (``bin_state``) and each bay's scene graph (``load_scene``,
:mod:`shared.loads`). :func:`bin_scene` answers "what stands in this bin's bay"; :func:`import_wms_stock` stores
the WMS's view of which bins hold stock (one revision of the ``wms_stock`` stage, kept whatever the retention
says), and :func:`stock_discrepancies` lists the bins where the robots saw otherwise, leaving out bins they did
not see well (state ``unknown``, or fewer views than asked).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from atlas.bins import BinIndex, BinNotFoundError, bin_index, bin_states, no_bin
from atlas.cache import RevisionCache
from atlas.errors import NotInMapError
from shared.loads import BinOccupancy, Occupancy, SceneGraph, SceneNode, occupancy_from_feature, scene_from_feature
from shared.store import MapInfo, MapStore, Revision, WmsStock
from shared.vocabulary import FeatureKind

WMS_STOCK_STAGE = "wms_stock"
"""The stage named by revisions that import a WMS stock list."""
MIN_VIEWS = 2
"""Default: a bin seen fewer times than this is not reported as a discrepancy (nor as agreeing)."""
FEW_BAYS = 16
"""Up to this many bays, :func:`with_evidence` reads their scenes one by one; more, every scene at once."""


class SceneNotFoundError(NotInMapError):
    """A bin whose bay has no scene (the robots have not seen it, or it is in no bay)."""


class NoStockListError(NotInMapError):
    """A map without an imported WMS stock list."""


@dataclass(frozen=True, slots=True)
class BinScene:
    """The scene graph of a bin's bay, with the bin's own state."""

    bin_id: str
    """The id the client named the bin by (its WMS id or Aisle's)."""
    detected_id: str
    """Aisle's id of the bin."""
    occupancy: BinOccupancy
    scene: SceneGraph
    state_revision_id: int
    """The revision that wrote the bin's state."""
    scene_revision_id: int
    """The revision that wrote the scene."""


def bin_scene(store: MapStore, cache: RevisionCache, map_info: MapInfo, bin_id: str, *, revision: int | None
              ) -> BinScene:
    """The scene of the bay of bin ``bin_id`` (its WMS id or Aisle's) as of ``revision`` (default: now).

    Raises
    ------
    BinNotFoundError
        The map has no such bin then.
    SceneNotFoundError
        The bin has no state naming its bay, or the bay no scene.
    """
    index = bin_index(store, cache, map_info.id, revision)
    detected = index.detected_id(bin_id)
    if store.feature(map_info.id, FeatureKind.BIN, detected, revision=revision) is None:
        raise no_bin(map_info, bin_id, revision)
    state = store.feature(map_info.id, FeatureKind.BIN_STATE, detected, revision=revision)
    occupancy = None if state is None else occupancy_from_feature(state.feature)
    when = "now" if revision is None else f"at revision {revision}"
    if state is None or occupancy is None or occupancy.bay is None:
        raise SceneNotFoundError(f"bin {bin_id!r} of map {map_info.name!r} has no scene {when}: the robots have not "
                                 "seen its bay")
    scene = store.feature(map_info.id, FeatureKind.LOAD_SCENE, occupancy.bay, revision=revision)
    if scene is None:
        raise SceneNotFoundError(f"bay {occupancy.bay!r} of bin {bin_id!r} (map {map_info.name!r}) has no scene "
                                 f"{when}")
    return BinScene(bin_id, detected, occupancy, scene_from_feature(scene.feature), state.revision_id,
                    scene.revision_id)


def import_wms_stock(store: MapStore, map_id: int, items: Sequence[WmsStock], *, complete: bool) -> Revision:
    """Store ``items`` as the map's WMS stock list (one new revision of stage ``wms_stock``).

    ``complete``: the list names every bin that holds stock, so a bin it leaves out is empty as the WMS sees it.
    """
    return store.replace_wms_stock(map_id, items, stage=WMS_STOCK_STAGE, summary={"complete": complete})


@dataclass(frozen=True, slots=True)
class StockDiscrepancy:
    """A bin the WMS and the robots disagree about."""

    bin_id: str
    """The id the WMS names it by (its own when a WMS bin list matched it, else Aisle's)."""
    detected_id: str
    """Aisle's id of the bin."""
    wms: WmsStock
    """What the WMS says (for a bin a complete list leaves out: holds no stock)."""
    seen: BinOccupancy
    """What the robots saw: the state, its confidence, the views, when last seen, the objects."""
    state_revision_id: int
    evidence: tuple[SceneNode, ...] = ()
    """The scene nodes of the objects the robots saw in the bin (none when they saw it empty); filled in by
    :func:`with_evidence`."""


@dataclass(frozen=True, slots=True)
class StockCheck:
    """The WMS stock list against what the robots saw, as of one revision."""

    stock_revision_id: int
    """The revision that imported the stock list."""
    complete: bool
    min_views: int
    discrepancies: list[StockDiscrepancy]
    """Sorted by the WMS's bin id."""
    listed: int
    """Bins on the stock list."""
    agreeing: int
    """Bins checked (seen well) where both agree."""
    not_seen_well: int
    """Bins on the list left unchecked: state unknown or none, or fewer views than ``min_views``."""


def stock_discrepancies(store: MapStore, cache: RevisionCache, map_info: MapInfo, *, revision: int | None,
                        min_views: int = MIN_VIEWS) -> StockCheck:
    """The bins where what the robots saw disagrees with the WMS stock list live at ``revision`` (default: now).

    A bin counts only when the robots saw it well: state ``empty`` or ``occupied`` resting on at least
    ``min_views`` views; a bin seen as occupied is a discrepancy where the WMS says it holds no stock, and one seen
    empty where the WMS says it does. With a ``complete`` list, occupied bins it leaves out are discrepancies too.
    WMS ids are taken through the imported WMS bin list's matching where there is one.

    Raises
    ------
    NoStockListError
        No stock list was imported by then.
    """
    imported = store.latest_revision(map_info.id, stage=WMS_STOCK_STAGE, at_or_before=revision)
    if imported is None:
        raise NoStockListError(f"map {map_info.name!r} has no WMS stock list; import one with PUT "
                               f"/v1/maps/{map_info.name}/wms-stock")
    complete = imported.summary.get("complete") is True
    index = bin_index(store, cache, map_info.id, revision)
    states = {key: (occupancy_from_feature(stored.feature), stored.revision_id)
              for key, stored in bin_states(store, map_info.id, revision).items()}
    listed = store.wms_stock(map_info.id, revision=revision)
    checks = [(item, index.detected_id(item.bin_id)) for item in listed]
    if complete:
        named = {detected for _, detected in checks}
        checks += [(WmsStock(_wms_id(index, key), holds_stock=False), key) for key, (seen, _) in states.items()
                   if key not in named and seen.state == Occupancy.OCCUPIED]
    found: list[StockDiscrepancy] = []
    agreeing = unseen = 0
    for wms, detected in checks:
        state = states.get(detected)
        if state is None or state[0].state == Occupancy.UNKNOWN or state[0].views < min_views:
            unseen += 1
            continue
        seen, state_revision = state
        if (seen.state == Occupancy.OCCUPIED) == wms.holds_stock:
            agreeing += 1
            continue
        found.append(StockDiscrepancy(wms.bin_id, detected, wms, seen, state_revision))
    found.sort(key=lambda item: item.bin_id)
    return StockCheck(imported.id, complete, min_views, found, len(listed), agreeing, unseen)


def _wms_id(index: BinIndex, detected: str) -> str:
    """The WMS's id of bin ``detected`` where a WMS bin list matched it, else Aisle's."""
    wms_id = None if index.matching is None else index.matching.wms_of(detected)
    return wms_id or detected


def with_evidence(store: MapStore, map_info: MapInfo, items: Sequence[StockDiscrepancy], *, revision: int | None
                  ) -> list[StockDiscrepancy]:
    """``items`` with their evidence: the scene nodes of the objects each bin's state names, from its bay's scene
    as of ``revision`` (a few bays are read one by one, more all at once)."""
    bays = {item.seen.bay for item in items if item.seen.objects and item.seen.bay is not None}
    if len(bays) <= FEW_BAYS:
        stored = [found for bay in sorted(bays)
                  if (found := store.feature(map_info.id, FeatureKind.LOAD_SCENE, bay, revision=revision)) is not None]
    else:
        stored = [found for found in store.features(map_info.id, kinds=[FeatureKind.LOAD_SCENE], revision=revision)
                  if found.feature.key in bays]
    nodes = {found.feature.key: {node.id: node for node in scene_from_feature(found.feature).nodes}
             for found in stored}
    return [replace(item, evidence=tuple(nodes[item.seen.bay][name] for name in item.seen.objects
                                         if item.seen.bay in nodes and name in nodes[item.seen.bay]))
            for item in items]


__all__ = [
    "FEW_BAYS",
    "MIN_VIEWS",
    "WMS_STOCK_STAGE",
    "BinNotFoundError",
    "BinScene",
    "NoStockListError",
    "SceneNotFoundError",
    "StockCheck",
    "StockDiscrepancy",
    "bin_scene",
    "import_wms_stock",
    "stock_discrepancies",
    "with_evidence",
]
