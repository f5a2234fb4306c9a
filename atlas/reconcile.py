"""Reconciling the WMS's own bin numbering with the bins Aisle detected.

A site keeps its numbering: each WMS bin is matched to at most one detected bin, first by equal
id (the site adopted Aisle's ids), then by position for WMS bins that give one (nearest detected
bin centre within a tolerance, on the same level when both know it, each detected bin used once,
closest pairs first). :func:`wms_matching` matches the WMS list live at a revision to the bins live then.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from shared.bins import Bin
from shared.store import MapStore, WmsBin
from shared.vocabulary import FeatureKind

WMS_STAGE = "wms"
"""Stage name of the revisions that import the WMS's bin list."""
DEFAULT_TOLERANCE_M = 0.5
"""Matching tolerance of a WMS list imported without one, metres."""


@dataclass(frozen=True, slots=True)
class DetectedBin:
    """What matching needs of a detected bin: its id, centre (map metres) and level if known."""

    id: str
    x_m: float
    y_m: float
    level: int | None = None


@dataclass(frozen=True, slots=True)
class Match:
    wms_id: str
    detected_id: str
    by: str
    """``id`` (same id on both sides) or ``position``."""
    distance_m: float | None
    """Between the WMS position and the detected centre; None when the WMS gave no position."""


@dataclass(frozen=True, slots=True)
class Reconciliation:
    matched: list[Match]
    missing_in_map: list[str]
    """WMS bin ids with no detected bin."""
    unknown_to_wms: list[str]
    """Detected bin ids the WMS does not list."""

    def by_detected(self) -> dict[str, Match]:
        return {m.detected_id: m for m in self.matched}

    def by_wms(self) -> dict[str, Match]:
        return {m.wms_id: m for m in self.matched}


def reconcile(wms: Sequence[WmsBin], detected: Sequence[DetectedBin], *, tolerance_m: float = 0.5
              ) -> Reconciliation:
    """Match WMS bins to detected bins (see the module docstring).

    Parameters
    ----------
    wms : sequence of WmsBin
        The WMS's bin list.
    detected : sequence of DetectedBin
        Aisle's bins.
    tolerance_m : float
        Largest distance between a WMS position and a detected bin centre that still matches, metres;
        about half a bay width keeps neighbouring bins apart.

    Returns
    -------
    Reconciliation
        Matches (sorted by WMS id), WMS ids missing in the map and detected ids unknown to the WMS.
    """
    if not tolerance_m > 0:
        raise ValueError(f"tolerance_m must be positive, got {tolerance_m}")
    detected_ids = {d.id for d in detected}
    by_id = {d.id: d for d in detected}
    matches = [Match(w.wms_id, w.wms_id, "id", _distance(w, by_id[w.wms_id])) for w in wms if w.wms_id in by_id]
    taken_wms = {m.wms_id for m in matches}
    taken_detected = {m.detected_id for m in matches}
    free_detected = [d for d in detected if d.id not in taken_detected]
    positioned = [w for w in wms if w.wms_id not in taken_wms and w.x_m is not None and w.y_m is not None]
    if free_detected and positioned:
        matches.extend(_by_position(positioned, free_detected, tolerance_m))
    matched_wms = {m.wms_id for m in matches}
    matched_detected = {m.detected_id for m in matches}
    return Reconciliation(
        matched=sorted(matches, key=lambda m: m.wms_id),
        missing_in_map=sorted(w.wms_id for w in wms if w.wms_id not in matched_wms),
        unknown_to_wms=sorted(detected_ids - matched_detected),
    )


def _distance(w: WmsBin, d: DetectedBin) -> float | None:
    if w.x_m is None or w.y_m is None:
        return None
    return float(np.hypot(w.x_m - d.x_m, w.y_m - d.y_m))


def _by_position(wms: Sequence[WmsBin], detected: Sequence[DetectedBin], tolerance_m: float) -> list[Match]:
    """Closest pairs first, each bin used once, within ``tolerance_m`` and on compatible levels."""
    centres = np.array([(d.x_m, d.y_m) for d in detected], dtype=float)
    points = np.array([(w.x_m, w.y_m) for w in wms], dtype=float)
    tree = cKDTree(centres)
    k = min(8, len(detected))
    distances, neighbours = tree.query(points, k=k, distance_upper_bound=tolerance_m)
    distances = np.asarray(distances, dtype=float).reshape(len(wms), k)
    neighbours = np.asarray(neighbours).reshape(len(wms), k)
    rows, cols = np.nonzero(np.isfinite(distances))
    order = np.argsort(distances[rows, cols], kind="stable")
    used_wms: set[int] = set()
    used_detected: set[int] = set()
    out: list[Match] = []
    for i, j in zip(rows[order], cols[order], strict=True):
        w, d = int(i), int(neighbours[i, j])
        if w in used_wms or d in used_detected:
            continue
        level_w, level_d = wms[w].level, detected[d].level
        if level_w is not None and level_d is not None and level_w != level_d:
            continue
        used_wms.add(w)
        used_detected.add(d)
        out.append(Match(wms[w].wms_id, detected[d].id, "position", float(distances[i, j])))
    return out


@dataclass(frozen=True, slots=True)
class WmsMatching:
    """The WMS list imported by revision ``revision_id`` matched to the detected bins."""

    reconciliation: Reconciliation
    tolerance_m: float
    revision_id: int
    """The revision that imported the WMS list."""

    def wms_of(self, detected_id: str) -> str | None:
        """The WMS id detected bin ``detected_id`` is matched to, if any."""
        match = self.reconciliation.by_detected().get(detected_id)
        return None if match is None else match.wms_id

    def detected_of(self, wms_id: str) -> str | None:
        """Aisle's id of the bin WMS bin ``wms_id`` is matched to, if any."""
        match = self.reconciliation.by_wms().get(wms_id)
        return None if match is None else match.detected_id


def detected_bin(record: Bin) -> DetectedBin:
    """What matching needs of a bin."""
    return DetectedBin(record.id, record.centre[0], record.centre[1], record.level)


def wms_matching(store: MapStore, map_id: int, revision: int | None) -> WmsMatching | None:
    """The WMS list live at ``revision`` (default: now) matched to the bins live then, or None if no list was
    imported."""
    imported = store.latest_revision(map_id, stage=WMS_STAGE, at_or_before=revision)
    if imported is None:
        return None
    tolerance = imported.summary.get("tolerance_m", DEFAULT_TOLERANCE_M)
    tolerance_m = float(tolerance) if isinstance(tolerance, int | float) and tolerance > 0 else DEFAULT_TOLERANCE_M
    detected = [detected_bin(Bin.from_feature(item.feature))
                for item in store.features(map_id, kinds=[FeatureKind.BIN], revision=revision)]
    result = reconcile(store.wms_bins(map_id, revision=revision), detected, tolerance_m=tolerance_m)
    return WmsMatching(result, tolerance_m, imported.id)
