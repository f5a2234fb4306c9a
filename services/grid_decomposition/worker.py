"""The grid-decomposition worker: occupancy revisions in, place labels, regions and topology out.

It follows the map events (``/aisle/map_events``): an event of this map that updated ``source_layer``, or a new
label table, makes it look at the store at once (a look lists the revisions since the last one; no grid is read).
The bus is fire-and-forget and a writer in another process announces nothing here, so the store is also looked at
every ``safety_poll_period_s``, and once on start.

When the layer changed and ``min_period_s`` has passed since the last attempt, the newest layer is compared with
the last decomposed one (:func:`changed_fraction`); at ``min_change_fraction`` or more it is decomposed and ONE
revision is committed: label and segment layers (meta ``source_layer``, ``source_revision``), features, region graph,
regions keyed as the stored ones they overlap (:func:`carry_keys`). The stored decomposition and the grid it was made
from are its prior (:func:`region_prior`): a region over map that did not change keeps its extent, so keys do not
flicker on a growing map. A new label table (stage ``label_table``), or new rack rows of the pillar stage
(:class:`KnownRacks`, evidence of racks), re-decompose the current grid at once (new racks without the prior: they
may move any region).
A grid the decomposition cannot use is counted as ``decomposition_errors`` and becomes the reference all the same.
On start the source revision is read back from the stored label layer: a grid is not decomposed twice.
"""

from __future__ import annotations

import logging
import threading
import time

from services.grid_decomposition.change import changed_fraction
from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.keys import NEXT_ID_KEY, carry_keys, region_prior
from services.grid_decomposition.known_racks import KNOWN_RACKS_STAGE, KnownRacks
from services.grid_decomposition.pipeline import decompose
from services.grid_decomposition.records import decomposition_features, decomposition_layers, decomposition_topology
from services.grid_decomposition.semantics import parse_label_table
from shared.collector import collector_held
from shared.places import LABEL_OVERRIDES_KEY, LABEL_TABLE_STAGE
from shared.settings import DecompositionSettings
from shared.store import GridLayer, Revision, RevisionWrite, StoredLayer, StoreUnavailableError
from shared.vocabulary import PlaceLabel
from shared.worker import IDLE_WAIT_S, StageContext, checked

log = logging.getLogger(__name__)

_PAGE = 100
_RETRY_S = 2.0  # how soon the store is looked at again after it was unavailable, seconds


class DecompositionStage:
    """Stage ``grid_decomposition``, built from its settings section; see the module docstring."""

    def __init__(self, context: StageContext, settings: DecompositionSettings) -> None:
        self.context = context
        self.settings = settings = checked(settings, DecompositionError)
        self.source_layer = settings.source_layer
        self.layer_names = (settings.label_layer, settings.segment_layer)
        self.events = context.map_events()
        self._seen_revision: int | None = None
        self._pending, self._relabel = True, False
        self._checked_revision: int | None = None
        self._reference: GridLayer | None = None
        self._decomposed: GridLayer | None = None  # the grid the stored decomposition was made from
        self._last_attempt = -float("inf")
        self._overrides: dict[int, PlaceLabel] = {}
        self.racks = KnownRacks()

    def run(self, stop: threading.Event) -> None:
        look_at = 0.0  # monotonic time of the next look at the store: at once on start
        while not stop.is_set():
            if time.monotonic() >= look_at:
                try:
                    self._look()
                    look_at = time.monotonic() + self.settings.safety_poll_period_s
                    if self._pending:  # held back by min_period_s, or its revision was not stored
                        held = self._last_attempt + self.settings.min_period_s
                        look_at = min(look_at, max(held, time.monotonic() + _RETRY_S))
                except StoreUnavailableError as err:
                    self.context.count("store_unavailable")
                    log.warning("store unavailable, will retry: %s", err)
                    look_at = time.monotonic() + _RETRY_S
            if self._announced(timeout_s=min(IDLE_WAIT_S, max(0.0, look_at - time.monotonic()))):
                look_at = 0.0

    def _announced(self, *, timeout_s: float) -> bool:
        """Whether map events (the first awaited up to ``timeout_s``) announced work for this map."""
        announced, item = False, self.events.receive(timeout_s)
        while item is not None:
            event = item.message
            announced |= str(event.map_name) == self.context.map.name and (
                self.source_layer in event.layers_updated or event.stage in (LABEL_TABLE_STAGE, KNOWN_RACKS_STAGE))
            item = self.events.receive()
        return announced

    def _look(self) -> None:
        if self._seen_revision is None:
            self._seen_revision = self._resume()
        elif self._source_updated(self._seen_revision):
            self._pending = True
        if not self._pending or time.monotonic() - self._last_attempt < self.settings.min_period_s:
            return
        stored = self.context.store.layer(self.context.map.id, self.source_layer)
        previous = self.context.store.layer(self.context.map.id, self.layer_names[1])
        racks_changed = self.racks.refresh(self.context.store, self.context.map.id)
        self._pending = False
        relabel, self._relabel = self._relabel or racks_changed, False
        if stored is None or (stored.revision_id == self._checked_revision and not relabel):
            return
        self._checked_revision = stored.revision_id
        fraction = 1.0 if self._reference is None or relabel else changed_fraction(self._reference, stored.layer)
        if fraction < self.settings.min_change_fraction:
            self.context.count("small_changes_skipped")
            log.debug("%s revision %d changed by %.4f, below %.4f: not decomposed", self.source_layer,
                      stored.revision_id, fraction, self.settings.min_change_fraction)
            return
        self._decompose(stored, None if previous is None else previous.layer, prior=not racks_changed)

    def _resume(self) -> int:
        """The newest revision id (watched after); the stored decomposition's source becomes the reference."""
        store, map_id = self.context.store, self.context.map.id
        latest = store.latest_revision(map_id)
        table = store.latest_revision(map_id, stage=LABEL_TABLE_STAGE)
        if table is not None:
            self._take_label_table(table)
        labels = store.layer(map_id, self.layer_names[0])
        source = labels.layer.meta.get("source_revision") if labels is not None else None
        if isinstance(source, int):
            reference = store.layer(map_id, self.source_layer, revision=source)
            if reference is not None and reference.revision_id == source:
                self._reference = self._decomposed = reference.layer
                self._checked_revision = source
                log.info("resuming: %s revision %d is decomposed already", self.source_layer, source)
        return latest.id if latest is not None else 0

    def _source_updated(self, seen: int) -> bool:
        """Whether a revision after ``seen`` updated the source layer; pages through them, moving the mark."""
        updated = False
        while True:
            page = self.context.store.revisions(self.context.map.id, after_id=seen, limit=_PAGE)
            if not page:
                return updated
            seen = self._seen_revision = page[-1].id
            updated |= any(self.source_layer in r.summary.get("layers_updated", ()) for r in page)
            updated |= self.racks.note(page)
            tables = [r for r in page if r.stage == LABEL_TABLE_STAGE]
            if tables and self._take_label_table(tables[-1]):
                self._relabel = updated = True
            if len(page) < _PAGE:
                return updated

    def _take_label_table(self, revision: Revision) -> bool:
        """Adopt the overrides of a label-table revision; whether they differ from the current ones."""
        raw = revision.summary.get(LABEL_OVERRIDES_KEY, {})
        try:
            overrides = parse_label_table(raw if isinstance(raw, dict) else {})
        except DecompositionError as err:
            self.context.count("bad_label_tables")
            log.warning("label table of revision %d ignored: %s", revision.id, err)
            return False
        changed, self._overrides = overrides != self._overrides, overrides
        log.info("label table of revision %d: %s", revision.id,
                 {c: label.name.lower() for c, label in sorted(overrides.items())} or "automatic")
        return changed

    def _decompose(self, stored: StoredLayer, previous: GridLayer | None, *, prior: bool) -> None:
        """Decompose ``stored`` and commit it, keyed as ``previous`` (the stored segment layer); with ``prior``, the
        stored decomposition is kept where the map did not change since the grid it was made from."""
        layer, self._last_attempt, start = stored.layer, time.monotonic(), time.perf_counter()
        try:
            racks = self.racks.on_grid(layer)
            kept = (region_prior(previous, self._decomposed, layer)
                    if prior and previous is not None and self._decomposed is not None else None)
            with collector_held():  # the first in a process imports the step libraries: no full collections
                result = decompose(layer.data, resolution_m=layer.resolution_m,
                                   origin_xy_m=(layer.origin_x_m, layer.origin_y_m),
                                   neck_half_width_m=self.settings.neck_half_width_m,
                                   door_max_width_m=self.settings.door_max_width_m,
                                   label_overrides=self._overrides or None, known_places=racks, prior=kept)
            result, ids = carry_keys(result, previous)
            source = {"source_layer": self.source_layer, "source_revision": stored.revision_id}
            layers = decomposition_layers(result, label_layer=self.layer_names[0], segment_layer=self.layer_names[1],
                                          meta={**source, NEXT_ID_KEY: ids.next_id})
        except DecompositionError as err:
            self._reference = layer
            self.context.count("decomposition_errors")
            log.warning("%s revision %d (%d x %d cells) not decomposed: %s", self.source_layer, stored.revision_id,
                        layer.data.shape[1], layer.data.shape[0], err)
            return
        seconds = time.perf_counter() - start
        aisles = self.racks.names(result)
        features = decomposition_features(result, known_racks=None if racks is None else racks.storage, aisles=aisles)
        write = RevisionWrite(self.context.name, layers=layers, features=features,
                              topology=decomposition_topology(result, aisles=aisles), summary={
                                  **source, "regions": len(result.regions), "regions_kept": ids.carried,
                                  "decomposition_s": round(seconds, 3), LABEL_OVERRIDES_KEY: {
                                      str(c): label.name.lower() for c, label in sorted(self._overrides.items())}})
        self.context.counters.set(f"{self.context.name}.last_decomposition_ms", round(seconds * 1000))
        revision = self.context.commit(write)
        if revision is None:  # store down: counted by commit; try this grid again
            self._checked_revision, self._pending = None, True
            return
        self._reference = self._decomposed = layer
        self.context.count("decompositions")
        log.info("revision %d: %s revision %d decomposed in %.2f s: %d regions, %s", revision.id, self.source_layer,
                 stored.revision_id, seconds, len(result.regions),
                 {str(kind): len(items) for kind, items in features.items() if items})


def decomposition_stage(context: StageContext) -> DecompositionStage:
    """The stage built from its settings section, ``context.settings.decomposition``."""
    return DecompositionStage(context, context.settings.decomposition)
