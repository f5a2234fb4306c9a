"""The live state of each map in memory: what live reads (no ``?revision=``) of features and bins are answered
from, so they read nothing from the database.

Per map, a :class:`LiveMap` holds the live feature index and the bin index of one revision. It is refreshed
in the background, one refresh per map at a time, while requests keep being answered from the one before:

* by a look at the map's newest revision id, started by a request once the last look is more than half of
  ``staleness_s`` old: one query for all the requests of that moment;
* at once when a stage announces a revision on the bus (``/aisle/map_events``), if the app has a bus;
* at once when the API itself writes a revision (:meth:`LiveMaps.written`); the next reads wait for it, so a
  client reads its own writes.

A refresh reads only what the revisions since the last one changed (:meth:`MapStore.feature_rows_changed`).
A request waits for a refresh only when the last look is more than ``staleness_s`` old (the first request
after a quiet spell, or a database slower than that), so a live answer is at most ``staleness_s`` behind the
store: it covers every revision committed that long before the request.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from typing import Any

from atlas.bins import BinAnswer, BinIndex, answer_stored, bin_index
from atlas.cache import RevisionCache
from atlas.errors import AtlasConfigError
from atlas.features import FeatureIndex, stored_feature
from atlas.reconcile import WMS_STAGE
from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus, DropPolicy
from shared.store import MapInfo, MapStore, Revision
from shared.store.store import FeatureRow
from shared.vocabulary import FeatureKind, LayerName
from shared.worker import MAP_EVENTS_TOPIC

_BIN = FeatureKind.BIN.value
"""The bin kind as a plain string: live look-ups hash it, and a plain string hashes without a Python call."""
_BIN_STATE = FeatureKind.BIN_STATE.value

log = logging.getLogger(__name__)

STALENESS_S = 0.2
"""Default bound on how far behind the store a live answer may be, seconds."""
CATCH_UP_REVISIONS = 100
"""Revisions a refresh reads through one by one; after more than this many, it reads every live feature."""
BIN_PLACE_KINDS = frozenset({FeatureKind.JUNCTION, FeatureKind.CORRIDOR})
"""Feature kinds a bin answer reads besides the bin (its corridor and nearest junction)."""


@dataclass(frozen=True, slots=True)
class LiveMap:
    """One map as of revision ``revision_id``: its live features and what bin answers need besides the bin."""

    revision_id: int
    features: FeatureIndex
    bins: BinIndex
    bin_json: dict[tuple[int, int], bytes] = field(default_factory=dict, repr=False)
    """Bin answers (JSON) made with ``bins`` so far, by the feature row ids of the bin and of its state (0 without
    one); the API fills it."""

    def bin_row(self, bin_id: str) -> FeatureRow | None:
        """The live row of the bin a client names ``bin_id`` (its WMS id or Aisle's), or None."""
        return self.features.feature(_BIN, self.bins.detected_id(bin_id))

    def state_row(self, row: FeatureRow) -> FeatureRow | None:
        """The live ``bin_state`` row of the bin of live row ``row``, or None."""
        return self.features.feature(_BIN_STATE, row.key)

    def bin_answer(self, row: FeatureRow, state: FeatureRow | None = None) -> BinAnswer:
        """The answer about the bin of live row ``row`` (with its live state row ``state``)."""
        return answer_stored(stored_feature(row), self.bins, None if state is None else stored_feature(state))


@dataclass(slots=True)
class _State:
    info: MapInfo
    live: LiveMap | None = None
    checked_at: float = -math.inf
    """Clock time just before the newest revision id was last read: ``live`` covers every revision before."""
    wanted: int = 0
    """A revision this API wrote: answers must cover it."""
    pending: Future[None] | None = None
    """The refresh under way, if any."""


class LiveMaps:
    """The live state of every map this API process serves (see the module docstring).

    Parameters
    ----------
    store : MapStore
        The store the maps are read from.
    cache : RevisionCache
        Where decoded place layers are kept (shared with the routes that read them at a revision).
    staleness_s : float
        How far behind the store a live answer may be, seconds (>= 0; 0: every answer looks at the store).
    clock : callable, optional
        Monotonic seconds; tests pass a fake one.
    """

    def __init__(self, store: MapStore, cache: RevisionCache, *, staleness_s: float = STALENESS_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not (math.isfinite(staleness_s) and staleness_s >= 0):
            raise AtlasConfigError(f"live staleness must be a number of seconds >= 0, not {staleness_s}")
        self.store = store
        self.cache = cache
        self.staleness_s = staleness_s
        self._clock = clock
        self._states: dict[int, _State] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._listener: threading.Thread | None = None

    async def get(self, map_info: MapInfo) -> LiveMap | None:
        """The live state of the map, at most ``staleness_s`` behind the store; None while it has no revisions.

        Waits only when the state is older than that, or older than a revision this API wrote.
        """
        state = self._state(map_info)
        arrived = self._clock()
        while not self._fresh(state, arrived):
            await asyncio.wrap_future(self._refresh_soon(state))
        return state.live

    def peek(self, map_info: MapInfo) -> LiveMap | None:
        """The live state of the map if :meth:`get` would return it without waiting, else None."""
        state = self._states.get(map_info.id)
        return None if state is None or not self._fresh(state, self._clock()) else state.live

    def _fresh(self, state: _State, arrived: float) -> bool:
        """Whether ``state`` may answer a request that arrived at ``arrived``; starts a refresh when it is due."""
        live, checked_at = state.live, state.checked_at
        if not ((checked_at >= arrived or arrived - checked_at <= self.staleness_s)
                and (state.wanted == 0 if live is None else live.revision_id >= state.wanted)):
            return False
        if arrived - checked_at > self.staleness_s / 2:
            self._refresh_soon(state)
        return True

    def written(self, map_info: MapInfo, revision: Revision) -> None:
        """Note that this API wrote ``revision``: refresh now, and have reads wait until they cover it."""
        state = self._state(map_info)
        with self._lock:
            state.wanted = max(state.wanted, revision.id)
        self._refresh_soon(state)

    def changed(self, map_name: str) -> None:
        """Note that map ``map_name`` has a new revision (announced on the bus): refresh it in the background."""
        with self._lock:
            states = [state for state in self._states.values() if state.info.name == map_name]
        for state in states:
            self._refresh_soon(state)

    def warm(self, maps: Sequence[MapInfo]) -> None:
        """Start building the live state of ``maps`` in the background, so their first reads need not wait."""
        for map_info in maps:
            self._refresh_soon(self._state(map_info))

    def follow(self, bus: Bus) -> None:
        """Refresh maps as the revisions announced on ``bus`` come, until :meth:`close`."""
        subscription = bus.subscribe(MAP_EVENTS_TOPIC, messages.MAP_EVENT, namespaces=[WORKER_NAMESPACE],
                                     policy=DropPolicy.KEEP_NEWEST, maxsize=64, name="api.map_events")

        def listen() -> None:
            try:
                while not self._stop.is_set():
                    received = subscription.receive(timeout=0.5)
                    if received is not None:
                        self.changed(str(received.message.map_name))
            finally:
                subscription.close()

        self._listener = threading.Thread(target=listen, name="api-map-events", daemon=True)
        self._listener.start()

    def close(self) -> None:
        """Stop following the bus, and wait for the refreshes under way (so none reads a store being closed)."""
        self._stop.set()
        if self._listener is not None:
            self._listener.join()
        with self._lock:
            pending = [state.pending for state in self._states.values() if state.pending is not None]
        wait(pending)

    def _state(self, map_info: MapInfo) -> _State:
        state = self._states.get(map_info.id)
        if state is None:
            with self._lock:
                state = self._states.setdefault(map_info.id, _State(map_info))
        return state

    def _refresh_soon(self, state: _State) -> Future[None]:
        """The refresh of ``state`` under way, or a new one started in its own thread."""
        with self._lock:
            if state.pending is not None:
                return state.pending
            pending = state.pending = Future()
        threading.Thread(target=self._refresh, args=(state, pending), name=f"api-live-{state.info.name}",
                         daemon=True).start()
        return pending

    def _refresh(self, state: _State, pending: Future[None]) -> None:
        try:
            started = self._clock()
            latest = self.store.latest_revision(state.info.id)
            current = state.live
            if latest is None or current is None or current.revision_id < latest.id:
                state.live = None if latest is None else self._build(state.info.id, current, latest.id)
            state.checked_at = started
        except Exception as err:
            log.warning("refreshing the live state of map %s failed: %s", state.info.name, err)
            with self._lock:
                state.pending = None
            pending.set_exception(err)
        else:
            with self._lock:
                state.pending = None
            pending.set_result(None)

    def _build(self, map_id: int, current: LiveMap | None, latest_id: int) -> LiveMap:
        """The live state as of revision ``latest_id`` (or newer), from ``current`` where it still holds."""
        since = [] if current is None else self.store.revisions(map_id, after_id=current.revision_id,
                                                                limit=CATCH_UP_REVISIONS)
        if current is None or len(since) == CATCH_UP_REVISIONS:
            features = FeatureIndex.build(latest_id, self.store.live_feature_rows(map_id),
                                          None if current is None else current.features)
            return LiveMap(latest_id, features, bin_index(self.store, self.cache, map_id, latest_id))
        upto = max(latest_id, *(revision.id for revision in since))
        retired: set[int] = set()
        if any(_writes_features(revision.summary) for revision in since):
            changed = self.store.feature_rows_changed(map_id, after=current.revision_id, upto=upto)
            features = current.features.updated(upto, changed)
            retired = {row.id for row in changed if row.retired_revision_id is not None}
        else:
            features = current.features.moved_to(upto)
        if any(_changes_bins(revision, matched=current.bins.matching is not None) for revision in since):
            return LiveMap(upto, features, bin_index(self.store, self.cache, map_id, upto))
        # list() copies at once: the bins route adds answers meanwhile
        kept = {rows: answer for rows, answer in list(current.bin_json.items()) if retired.isdisjoint(rows)}
        return LiveMap(upto, features, current.bins, kept)


def _writes_features(summary: Any) -> bool:
    """Whether a revision summary records features written (or retired); unknown summaries count as yes."""
    return not isinstance(summary, Mapping) or bool(summary.get("features", True))


def _changes_bins(revision: Revision, *, matched: bool) -> bool:
    """Whether ``revision`` may change what bin answers read besides the bin: the WMS list and its matching
    (``matched``: one was imported, and it depends on the bins), corridors, junctions and place layers.

    Unknown summaries count as yes.
    """
    summary = revision.summary
    if not isinstance(summary, Mapping) or revision.stage == WMS_STAGE or "wms_bins" in summary:
        return True
    layers, kinds = summary.get("layers_updated"), summary.get("features")
    if not isinstance(layers, list) or not isinstance(kinds, Mapping):
        return True
    return (bool({LayerName.PLACE_LABELS, LayerName.PLACE_SEGMENTS} & set(layers))
            or bool(BIN_PLACE_KINDS & set(kinds)) or (matched and FeatureKind.BIN in kinds))
