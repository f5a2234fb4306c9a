"""Storage bins as a WMS wants them: by WMS id, with the corridor that leads to each and the nearest junction.

A bin answer needs, besides the bin (:class:`shared.bins.Bin`), the WMS matching, the corridors, the
junctions and the place layers of the same revision: :func:`bin_index` builds those once per revision of a
map (cached), and :func:`answer_bin` puts a bin and the index together.
"""

from __future__ import annotations

import enum
import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from atlas.cache import RevisionCache
from atlas.errors import NotInMapError
from atlas.grids import cached_layer, nearest_drivable_region, region_holding
from atlas.reconcile import WMS_STAGE, MatchBy, WmsMatching, detected_bin, reconcile, wms_matching
from shared.bins import Bin
from shared.loads import BinOccupancy, Occupancy, occupancy_from_feature
from shared.store import GridLayer, MapInfo, MapStore, Revision, StoredFeature, WmsBin
from shared.store.records import bounds
from shared.vocabulary import FeatureKind, LayerName

BBox = tuple[float, float, float, float]
"""(min_x, min_y, max_x, max_y), map-frame metres."""


class BinStatus(enum.StrEnum):
    """How a bin stands against the WMS's own bin list."""

    MATCHED = "matched"
    """Matched to a bin of the imported WMS list."""
    UNKNOWN_TO_WMS = "unknown_to_wms"
    """The imported WMS list lacks it."""
    UNRECONCILED = "unreconciled"
    """No WMS list was imported."""


class BinNotFoundError(NotInMapError):
    """No bin with the id asked for."""


@dataclass(frozen=True, slots=True)
class CorridorShape:
    """A corridor feature's key, the aisle it is (pillar mapping's aisles), and its outline."""

    key: str
    aisle: int | None
    rings: list[npt.NDArray[np.float32]]
    """Outer rings (N, 1, 2) in map metres, as cv2.pointPolygonTest takes them; holes are ignored."""

    def holds(self, x_m: float, y_m: float) -> bool:
        """Whether map point (x_m, y_m) is inside (or on) the outline."""
        return any(cv2.pointPolygonTest(ring, (x_m, y_m), False) >= 0 for ring in self.rings)


def _outer_rings(geometry: Mapping[str, Any]) -> list[npt.NDArray[np.float32]]:
    polygons = {"Polygon": [geometry.get("coordinates")], "MultiPolygon": geometry.get("coordinates")}.get(
        str(geometry.get("type")), [])
    return [np.asarray(polygon[0], dtype=np.float32).reshape(-1, 1, 2) for polygon in polygons or [] if polygon]


@dataclass(frozen=True, slots=True)
class PlaceRef:
    """A place a bin answer names: its feature key, its place label and (for the nearest junction) how far."""

    key: str
    label: str
    distance_m: float | None = None


@dataclass(frozen=True, slots=True)
class BinIndex:
    """What bin answers of one revision read besides the bins."""

    matching: WmsMatching | None
    junction_keys: list[str]
    junction_xy: npt.NDArray[np.float64]
    corridors: list[CorridorShape]
    labels: GridLayer | None
    segments: GridLayer | None

    def corridor_at(self, x_m: float, y_m: float, *, aisle: int | None = None) -> str | None:
        """Key of the corridor feature holding (x, y): the aisle's own (pillar mapping) when ``aisle`` is given
        and one holds the point, else any."""
        holding = [c for c in self.corridors if c.holds(x_m, y_m)]
        own = [c for c in holding if aisle is not None and c.aisle == aisle]
        chosen = own or holding
        return chosen[0].key if chosen else None

    def nearest_junction(self, x_m: float, y_m: float) -> tuple[str, float] | None:
        """(key, distance in metres) of the junction whose bounds' centre is nearest (x, y); None without any."""
        if not self.junction_keys:
            return None
        distance = np.hypot(self.junction_xy[:, 0] - x_m, self.junction_xy[:, 1] - y_m)
        best = int(np.argmin(distance))
        return self.junction_keys[best], float(distance[best])

    def place_at(self, x_m: float, y_m: float) -> tuple[str, str] | None:
        """(region key, label) of the drivable place at or within a metre of (x, y)."""
        if self.labels is None or self.segments is None:
            return None
        found = nearest_drivable_region(self.segments, self.labels, x_m, y_m)
        return None if found is None else (f"r{found[0]}", found[1])

    def storage_of(self, record: Bin) -> tuple[str, str] | None:
        """(region key, label) of the region holding most of the bin's footprint; None for a point bin."""
        if self.labels is None or self.segments is None or record.footprint is None:
            return None
        found = region_holding(self.segments, self.labels, record.footprint)
        return None if found is None else (f"r{found[0]}", found[1])

    def status_of(self, detected_id: str) -> tuple[BinStatus, str | None]:
        """The WMS status of bin ``detected_id`` and the WMS id it is matched to."""
        if self.matching is None:
            return BinStatus.UNRECONCILED, None
        wms_id = self.matching.wms_of(detected_id)
        return (BinStatus.UNKNOWN_TO_WMS if wms_id is None else BinStatus.MATCHED), wms_id

    def detected_id(self, bin_id: str) -> str:
        """Aisle's id of the bin a client names ``bin_id`` (a matched WMS id, else Aisle's own id)."""
        detected = None if self.matching is None else self.matching.detected_of(bin_id)
        return detected or bin_id


@dataclass(frozen=True, slots=True)
class BinAnswer:
    """One bin with what a WMS asks about it besides: its WMS id and status, where its access pose is."""

    bin: Bin
    status: BinStatus
    wms_id: str | None
    corridor: PlaceRef | None
    """The corridor feature the access pose is in: the bin's aisle where there is one, else any."""
    region: PlaceRef | None
    """The drivable region of the grid decomposition the access pose is in."""
    storage_region: PlaceRef | None
    """The region of the grid decomposition the bin's footprint lies in (a storage region where the racks are
    known)."""
    nearest_junction: PlaceRef | None
    stage: str
    """The stage that wrote the bin."""
    revision_id: int
    """The revision that wrote this version of the bin."""
    occupancy: BinOccupancy | None = None
    """What the robots saw in the bin (``bin_state``); None when nothing was stored for it."""
    occupancy_revision_id: int | None = None
    """The revision that wrote ``occupancy``."""

    @property
    def id(self) -> str:
        """The id to use: the WMS's when matched, else Aisle's."""
        return self.wms_id or self.bin.id

    @property
    def state(self) -> Occupancy:
        """The bin's occupancy state; ``unknown`` when nothing was stored for it."""
        return Occupancy.UNKNOWN if self.occupancy is None else self.occupancy.state


@dataclass(frozen=True, slots=True)
class BinSelection:
    """A page of bins and how many match over all pages."""

    bins: list[BinAnswer]
    total: int


def answer_bin(record: Bin, index: BinIndex, *, stage: str, revision_id: int, state: StoredFeature | None = None
               ) -> BinAnswer:
    """``record`` (written by ``stage`` in revision ``revision_id``) with its WMS id and status, its corridor,
    region and nearest junction, from ``index`` (of the same revision), and what the robots saw in it (``state``,
    its stored ``bin_state`` feature of that revision, if any)."""
    status, wms_id = index.status_of(record.id)
    x, y = record.reach
    place = index.place_at(x, y)
    storage = index.storage_of(record)
    corridor = index.corridor_at(x, y, aisle=record.aisle)
    nearest = index.nearest_junction(x, y)
    return BinAnswer(
        bin=record, status=status, wms_id=wms_id,
        corridor=None if corridor is None else PlaceRef(corridor, FeatureKind.CORRIDOR.value),
        region=None if place is None else PlaceRef(place[0], place[1]),
        storage_region=None if storage is None else PlaceRef(storage[0], storage[1]),
        nearest_junction=None if nearest is None else PlaceRef(nearest[0], FeatureKind.JUNCTION.value, nearest[1]),
        stage=stage, revision_id=revision_id,
        occupancy=None if state is None else occupancy_from_feature(state.feature),
        occupancy_revision_id=None if state is None else state.revision_id)


def answer_stored(stored: StoredFeature, index: BinIndex, state: StoredFeature | None = None) -> BinAnswer:
    """:func:`answer_bin` of a stored ``bin`` feature (and its stored ``bin_state``, if any)."""
    return answer_bin(Bin.from_feature(stored.feature), index, stage=stored.stage, revision_id=stored.revision_id,
                      state=state)


def bin_states(store: MapStore, map_id: int, revision: int | None) -> dict[str, StoredFeature]:
    """The stored ``bin_state`` features live at ``revision`` (default: now) by bin id (Aisle's); where several
    stages wrote one for a bin, the newest."""
    states: dict[str, StoredFeature] = {}
    for stored in store.features(map_id, kinds=[FeatureKind.BIN_STATE], revision=revision):
        known = states.get(stored.feature.key)
        if known is None or known.revision_id <= stored.revision_id:
            states[stored.feature.key] = stored
    return states


def bin_index(store: MapStore, cache: RevisionCache, map_id: int, revision: int | None) -> BinIndex:
    """The index as of ``revision`` (default: the newest), cached per revision."""
    at = revision
    if at is None:
        latest = store.latest_revision(map_id)
        at = 0 if latest is None else latest.id

    def build() -> BinIndex:
        junctions = store.features(map_id, kinds=[FeatureKind.JUNCTION], revision=at or None)
        xy = np.array([[(b[0] + b[2]) / 2, (b[1] + b[3]) / 2] for b in (bounds(j.feature.geometry) for j in junctions)],
                      dtype=float).reshape(-1, 2)
        corridors = [
            CorridorShape(c.feature.key, aisle if isinstance(aisle := c.feature.properties.get("aisle"), int) else None,
                          _outer_rings(c.feature.geometry))
            for c in store.features(map_id, kinds=[FeatureKind.CORRIDOR], revision=at or None)
        ]
        return BinIndex(
            matching=wms_matching(store, map_id, at or None),
            junction_keys=[j.feature.key for j in junctions],
            junction_xy=xy,
            corridors=corridors,
            labels=cached_layer(store, cache, map_id, LayerName.PLACE_LABELS, at or None),
            segments=cached_layer(store, cache, map_id, LayerName.PLACE_SEGMENTS, at or None),
        )

    return cache.get(("bins", store.url, map_id, at), build)


def import_wms_list(store: MapStore, cache: RevisionCache, map_id: int, items: Sequence[WmsBin], *,
                    tolerance_m: float, match_by: MatchBy = MatchBy.ID) -> tuple[Revision, WmsMatching]:
    """Store ``items`` as the map's WMS bin list (one new revision) and match them to the detected bins, once.

    The matching is made before the revision is written, from the bins live then, and put in ``cache`` as part of
    the new revision's bin index before the revision can be seen, so the live state that follows the revision
    (which live reads wait for) does not read the list back and match it again: for a list of 200 000 bins that
    takes seconds. If another revision was written meanwhile, the matching is made as of the new revision.

    Returns
    -------
    (Revision, WmsMatching)
        The revision written, and the list matched to the bins live at it.
    """
    basis = store.latest_revision(map_id)
    basis_index = None if basis is None else bin_index(store, cache, map_id, basis.id)
    detected = [detected_bin(Bin.from_feature(item.feature))
                for item in store.features(map_id, kinds=[FeatureKind.BIN],
                                           revision=None if basis is None else basis.id)]
    result = reconcile(items, detected, tolerance_m=tolerance_m, match_by=match_by)
    prepared: list[WmsMatching] = []

    def prepare(revision_id: int) -> None:
        """Runs while the map is locked: the newest revision others can see is the one just before this."""
        latest = store.latest_revision(map_id)
        if basis is not None and basis_index is not None and latest is not None and latest.id == basis.id:
            matching = WmsMatching(result, tolerance_m, match_by, revision_id)
            # a WMS revision changes nothing else a bin answer reads
            keys.append(("bins", store.url, map_id, revision_id))
            cache.get(keys[0], lambda: replace(basis_index, matching=matching))
            prepared.append(matching)

    keys: list[tuple[str, str, int, int]] = []
    try:
        summary = {"tolerance_m": tolerance_m, "match_by": match_by.value}
        written = store.replace_wms_bins(map_id, items, stage=WMS_STAGE, summary=summary, before_commit=prepare)
    except Exception:
        for key in keys:  # the revision was not stored after all (and its id may be given to another)
            cache.discard(key)
        raise
    if prepared:
        return written, prepared[0]
    fresh = wms_matching(store, map_id, written.id)
    assert fresh is not None  # the list was just written
    return written, fresh


def select_bins(store: MapStore, cache: RevisionCache, map_id: int, *, revision: int | None, bbox: BBox | None,
                aisle: int | None = None, row: str | None = None, level: int | None = None,
                id_prefix: str | None = None, status: BinStatus | None = None, occupancy: Occupancy | None = None,
                limit: int, offset: int) -> BinSelection:
    """Bins of the map (as of ``revision``) passing every filter given, sorted by the id to use, a page of them.

    ``bbox`` keeps bins whose bounds touch it (metres), ``id_prefix`` those whose id to use or Aisle's id
    starts so, ``occupancy`` those the robots saw so (``unknown`` includes bins with no state stored). Each bin is
    read once; only the page gets its corridor, region and nearest junction.
    """
    index = bin_index(store, cache, map_id, revision)
    states = bin_states(store, map_id, revision)
    chosen: list[tuple[str, int, Bin, StoredFeature]] = []
    for stored in store.features(map_id, kinds=[FeatureKind.BIN], bbox=bbox, revision=revision):
        record = Bin.from_feature(stored.feature)
        status_now, wms_id = index.status_of(record.id)
        shown = wms_id or record.id
        if ((aisle is None or record.aisle == aisle) and (row is None or record.row == row)
                and (level is None or record.level == level) and (status is None or status_now == status)
                and (id_prefix is None or shown.startswith(id_prefix) or record.id.startswith(id_prefix))
                and (occupancy is None or _state_of(states.get(record.id)) == occupancy)):
            chosen.append((shown, stored.revision_id, record, stored))
    chosen.sort(key=lambda entry: (entry[0], entry[1]))
    page = [answer_bin(record, index, stage=stored.stage, revision_id=stored.revision_id,
                       state=states.get(record.id))
            for _, _, record, stored in chosen[offset:offset + limit]]
    return BinSelection(page, len(chosen))


def stored_bin(store: MapStore, cache: RevisionCache, map_info: MapInfo, bin_id: str, *, revision: int
               ) -> BinAnswer:
    """Bin ``bin_id`` (its WMS id or Aisle's) as of ``revision``, read from the store.

    Raises
    ------
    BinNotFoundError
        The map has no such bin then.
    """
    index = bin_index(store, cache, map_info.id, revision)
    detected = index.detected_id(bin_id)
    found = store.feature(map_info.id, FeatureKind.BIN, detected, revision=revision)
    if found is None:
        raise no_bin(map_info, bin_id, revision)
    return answer_stored(found, index, store.feature(map_info.id, FeatureKind.BIN_STATE, detected, revision=revision))


def _state_of(stored: StoredFeature | None) -> Occupancy:
    return Occupancy.UNKNOWN if stored is None else occupancy_from_feature(stored.feature).state


def no_bin(map_info: MapInfo, bin_id: str, revision: int | None) -> BinNotFoundError:
    """The error for a bin the map does not have, saying where to look for the ones it does."""
    when = "now" if revision is None else f"at revision {revision}"
    return BinNotFoundError(f"map {map_info.name!r} has no bin {bin_id!r} {when}; list bins at "
                            f"/v1/maps/{map_info.name}/bins?id_prefix=")


def corridors_along(corridors: Sequence[CorridorShape], polyline: Sequence[tuple[float, float]], *,
                    step_m: float = 0.25) -> list[str]:
    """Keys of the corridors a polyline (map metres) runs through, in the order it enters them, each once.

    Where corridors overlap (an aisle crossing a cross aisle) both are listed, the one entered first first.
    """
    if not corridors or len(polyline) < 2:
        return []
    points = np.asarray(polyline, dtype=np.float64)
    samples = [points[0:1]]
    for a, b in itertools.pairwise(points):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / step_m)))
        samples.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    path = np.vstack(samples)
    order: list[tuple[int, str]] = []
    for corridor in corridors:
        inside = [k for k, (x, y) in enumerate(path) if corridor.holds(float(x), float(y))]
        if inside:
            order.append((inside[0], corridor.key))
    return [key for _, key in sorted(order)]
