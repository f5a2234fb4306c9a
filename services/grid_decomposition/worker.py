"""The grid-decomposition worker: occupancy revisions in, place labels, regions and topology out.

It watches the map store, not the bus: every ``poll_period_s`` it lists the revisions committed
since the last look (a small query on the revisions table; no grid is read) and notes whether one
updated ``source_layer``. The store is where the occupancy layer is authoritative: each version
has a revision id to record as the decomposition's source, a restarted worker finds it again,
and a worker in another process (or on another host sharing the database) sees the same grids.
``/aisle/map`` carries no revision and would cost a full decode every publish period.

When the layer changed and ``min_period_s`` has passed since the last attempt, the newest layer is
read and compared with the last decomposed one (:func:`changed_fraction`: the larger of the share
of known cells newly known or forgotten, and the share of obstacle cells whose free / uncertain /
occupied class changed). At ``min_change_fraction`` or more it is decomposed in the stage thread
(seconds on a large map) and ONE revision is committed: the label layer (uint8 :class:`PlaceLabel` codes, meta
``{"encoding": "place_labels", "classes": [...], "colours": [...], "source_layer", "source_revision"}``),
the segment layer (uint16 region ids), features (:func:`decomposition_features`: corridor,
junction, room, open_area, region (storage and unidentified, ``label`` property), wall, line) and
the region graph (edges with ``connection``). Smaller changes accumulate against the last
decomposed grid until they pass the threshold.

A person's label table (category -> label, a revision of stage ``label_table`` that the API writes)
is read on start and whenever a new one is committed; a new one re-decomposes the current grid at
once with those overrides, whatever its change, so the map is re-labelled as a new revision.

A grid the decomposition cannot use (no free cell, all unknown) is counted as
``decomposition_errors`` and logged; it becomes the reference all the same, so it is not retried
until it changes enough. On start the source revision is read back from the stored label layer:
a grid that was decomposed before a restart is not decomposed again.
"""

from __future__ import annotations

import logging
import threading
import time

from services.grid_decomposition.change import changed_fraction
from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.pipeline import decompose
from services.grid_decomposition.records import (
    decomposition_features,
    decomposition_layers,
    decomposition_topology,
)
from services.grid_decomposition.semantics import parse_label_table
from shared.places import LABEL_OVERRIDES_KEY, LABEL_TABLE_STAGE
from shared.store import GridLayer, Revision, RevisionWrite, StoredLayer, StoreUnavailableError
from shared.vocabulary import PlaceLabel
from shared.worker import StageContext

log = logging.getLogger(__name__)

_PAGE = 100


class DecompositionStage:
    """Stage ``grid_decomposition``; see the module docstring.

    Parameters
    ----------
    context
        The stage context.
    source_layer
        The occupancy layer decomposed (int8, -1 unknown, 0..100).
    label_layer, segment_layer
        Names of the layers written.
    min_change_fraction
        How much of the map must have changed since the last decomposition (:func:`changed_fraction`),
        in [0, 1].
    min_period_s
        Least time between two decompositions, seconds.
    poll_period_s
        How often the store is asked for new revisions, seconds.
    neck_half_width_m, door_max_width_m
        Passed to :func:`decompose` (metres).
    """

    def __init__(
        self,
        context: StageContext,
        *,
        source_layer: str = "occupancy",
        label_layer: str = "place_labels",
        segment_layer: str = "place_segments",
        min_change_fraction: float = 0.02,
        min_period_s: float = 10.0,
        poll_period_s: float = 2.0,
        neck_half_width_m: float = 0.5,
        door_max_width_m: float = 2.5,
    ) -> None:
        if not 0.0 <= min_change_fraction <= 1.0:
            raise DecompositionError(f"min_change_fraction must be in [0, 1], got {min_change_fraction}")
        if min_period_s < 0 or poll_period_s <= 0:
            raise DecompositionError(f"min_period_s must be >= 0 and poll_period_s > 0, got {min_period_s}, "
                                     f"{poll_period_s}")
        if source_layer in (label_layer, segment_layer) or label_layer == segment_layer:
            raise DecompositionError(f"layers {source_layer!r} (read), {label_layer!r}, {segment_layer!r} (written) "
                                     "must differ")
        if neck_half_width_m < 0 or door_max_width_m < 0:
            raise DecompositionError(f"neck_half_width_m and door_max_width_m must be >= 0, got {neck_half_width_m}, "
                                     f"{door_max_width_m}")
        self.context = context
        self.source_layer = source_layer
        self.layer_names = (label_layer, segment_layer)
        self.min_change_fraction = min_change_fraction
        self.min_period_s = min_period_s
        self.poll_period_s = poll_period_s
        self.neck_half_width_m = neck_half_width_m
        self.door_max_width_m = door_max_width_m
        self._seen_revision: int | None = None
        self._pending = True
        self._checked_revision: int | None = None
        self._reference: GridLayer | None = None
        self._last_attempt = -float("inf")
        self._overrides: dict[int, PlaceLabel] = {}
        self._relabel = False

    def run(self, stop: threading.Event) -> None:
        while True:
            try:
                self._poll()
            except StoreUnavailableError as err:
                self.context.count("store_unavailable")
                log.warning("store unavailable, will retry: %s", err)
            if stop.wait(self.poll_period_s):
                return

    # -- watching the store -----------------------------------------------------------------------

    def _poll(self) -> None:
        if self._seen_revision is None:
            self._seen_revision = self._resume()
        elif self._source_updated(self._seen_revision):
            self._pending = True
        if not self._pending or time.monotonic() - self._last_attempt < self.min_period_s:
            return
        stored = self.context.store.layer(self.context.map.id, self.source_layer)
        self._pending = False
        relabel, self._relabel = self._relabel, False
        if stored is None or (stored.revision_id == self._checked_revision and not relabel):
            return
        self._checked_revision = stored.revision_id
        fraction = 1.0 if self._reference is None or relabel else changed_fraction(self._reference, stored.layer)
        if fraction < self.min_change_fraction:
            self.context.count("small_changes_skipped")
            log.debug("%s revision %d changed by %.4f, below %.4f: not decomposed", self.source_layer,
                      stored.revision_id, fraction, self.min_change_fraction)
            return
        self._decompose(stored)

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
                self._reference = reference.layer
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
        changed = overrides != self._overrides
        self._overrides = overrides
        log.info("label table of revision %d: %s", revision.id,
                 {c: label.name.lower() for c, label in sorted(overrides.items())} or "automatic")
        return changed

    # -- decomposing ------------------------------------------------------------------------------

    def _decompose(self, stored: StoredLayer) -> None:
        layer = stored.layer
        self._last_attempt = time.monotonic()
        start = time.perf_counter()
        try:
            result = decompose(layer.data, resolution_m=layer.resolution_m,
                               origin_xy_m=(layer.origin_x_m, layer.origin_y_m),
                               neck_half_width_m=self.neck_half_width_m, door_max_width_m=self.door_max_width_m,
                               label_overrides=self._overrides or None)
            source = {"source_layer": self.source_layer, "source_revision": stored.revision_id}
            layers = decomposition_layers(result, label_layer=self.layer_names[0],
                                          segment_layer=self.layer_names[1], meta=source)
        except DecompositionError as err:
            self._reference = layer
            self.context.count("decomposition_errors")
            log.warning("%s revision %d (%d x %d cells) not decomposed: %s", self.source_layer, stored.revision_id,
                        layer.data.shape[1], layer.data.shape[0], err)
            return
        seconds = time.perf_counter() - start
        features = decomposition_features(result)
        write = RevisionWrite(
            self.context.name,
            layers=layers,
            features=features,
            topology=decomposition_topology(result),
            summary={**source, "regions": len(result.regions), "decomposition_s": round(seconds, 3),
                     LABEL_OVERRIDES_KEY: {str(c): label.name.lower() for c, label in sorted(self._overrides.items())}},
        )
        self.context.counters.set(f"{self.context.name}.last_decomposition_ms", round(seconds * 1000))
        revision = self.context.commit(write)
        if revision is None:
            self._checked_revision = None  # store down: counted by commit; try this grid again
            self._pending = True
            return
        self._reference = layer
        self.context.count("decompositions")
        log.info("revision %d: %s revision %d decomposed in %.2f s: %d regions, %s", revision.id, self.source_layer,
                 stored.revision_id, seconds, len(result.regions),
                 {kind: len(items) for kind, items in features.items() if items})


def decomposition_stage(context: StageContext) -> DecompositionStage:
    """The stage built from ``context.settings.decomposition``."""
    return DecompositionStage(context, **context.settings.decomposition.model_dump())
