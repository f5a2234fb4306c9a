"""Reconciling the WMS's own bin numbering with the bins Aisle detected.

A site keeps its numbering: each WMS bin is matched to at most one detected bin, first by equal
id (the site adopted Aisle's ids), then by position for WMS bins that give one (nearest detected
bin centre within a tolerance, on the same level when both know it, each detected bin used once,
closest pairs first). With ``match_by="position"`` a WMS bin that gives a position is matched by
position only (for a site whose ids look like Aisle's but count differently).

An id match whose WMS position lies further than the tolerance from the detected bin is kept (the ids
are equal) but reported as a :class:`Discrepancy`, and :func:`check_numbering` says at once when most
id matches are so: whether one constant shift of the ids (the site counts bays or aisles differently)
or one constant offset of the positions (the WMS surveyed in another frame) explains them.
:func:`wms_matching` matches the WMS list live at a revision to the bins live then.
"""

from __future__ import annotations

import enum
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from shared.bins import ID_PATTERN, XY, Bin
from shared.store import MapStore, WmsBin
from shared.vocabulary import FeatureKind

WMS_STAGE = "wms"
"""Stage name of the revisions that import the WMS's bin list."""
DEFAULT_TOLERANCE_M = 0.5
"""Matching tolerance of a WMS list imported without one, metres."""

_AISLE_ID = re.compile(ID_PATTERN)


class MatchBy(enum.StrEnum):
    """What a WMS bin is matched by first."""

    ID = "id"
    """Equal ids first, then the nearest position for WMS bins left over."""
    POSITION = "position"
    """The nearest position wherever the WMS gives one; equal ids only for WMS bins without a position."""


class Verdict(enum.StrEnum):
    """What the positions of the bins matched by id say about the site's numbering."""

    UNCHECKED = "unchecked"
    """No bin matched by id has a WMS position."""
    CONSISTENT = "consistent"
    """Every bin matched by id lies within the tolerance of its WMS position."""
    SOME_FAR = "some_far"
    """A few bins matched by id lie further (listed as discrepancies); most agree."""
    RENUMBERED = "renumbered"
    """Most bins matched by id lie far off, and one constant shift of the ids explains most of them: the site
    numbers aisles, bays or levels differently from Aisle's scheme."""
    SHIFTED = "shifted"
    """Most bins matched by id lie far off by one constant offset: the WMS positions are in another frame."""
    INCONSISTENT = "inconsistent"
    """Most bins matched by id lie far off, with no constant shift or offset explaining them."""


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
class Discrepancy:
    """A WMS bin matched by id to a detected bin further than the tolerance from the WMS position."""

    wms_id: str
    wms_xy: XY
    """Where the WMS says the bin is, map metres."""
    detected_xy: XY
    """Centre of the detected bin of that id, map metres."""
    distance_m: float
    nearest_detected_id: str | None
    """The detected bin within the tolerance of the WMS position (same level first), if any."""

    @property
    def delta_m(self) -> XY:
        """Detected centre minus WMS position, metres."""
        return self.detected_xy[0] - self.wms_xy[0], self.detected_xy[1] - self.wms_xy[1]


@dataclass(frozen=True, slots=True)
class IdShift:
    """A constant difference of Aisle's id numbers: the detected bin at a WMS bin's position has the WMS id's
    aisle, bay and level plus these."""

    aisle: int
    bay: int
    level: int
    support: int
    """How many far id matches it explains."""


@dataclass(frozen=True, slots=True)
class NumberingCheck:
    """How the WMS positions of the bins matched by id agree with the detected bins (see :class:`Verdict`)."""

    verdict: Verdict
    id_matches: int
    """Bins matched by id that have a WMS position."""
    far: int
    """Of them, those further than the tolerance from the detected bin."""
    median_distance_m: float | None
    """Median distance over the ``id_matches``, metres."""
    offset_m: XY | None
    """Median detected-minus-WMS offset over the ``id_matches``, metres."""
    offset_support: int
    """``id_matches`` within the tolerance once ``offset_m`` is taken away."""
    id_shift: IdShift | None
    """The commonest shift between a far bin's WMS id and the id of the detected bin at its WMS position."""
    message: str


@dataclass(frozen=True, slots=True)
class Reconciliation:
    matched: list[Match]
    missing_in_map: list[str]
    """WMS bin ids with no detected bin."""
    unknown_to_wms: list[str]
    """Detected bin ids the WMS does not list."""
    discrepancies: list[Discrepancy]
    """Id matches further than the tolerance from their WMS position, furthest first."""
    numbering: NumberingCheck

    def by_detected(self) -> dict[str, Match]:
        return {m.detected_id: m for m in self.matched}

    def by_wms(self) -> dict[str, Match]:
        return {m.wms_id: m for m in self.matched}


def reconcile(wms: Sequence[WmsBin], detected: Sequence[DetectedBin], *, tolerance_m: float = DEFAULT_TOLERANCE_M,
              match_by: MatchBy = MatchBy.ID) -> Reconciliation:
    """Match WMS bins to detected bins (see the module docstring).

    Parameters
    ----------
    wms : sequence of WmsBin
        The WMS's bin list.
    detected : sequence of DetectedBin
        Aisle's bins.
    tolerance_m : float
        Largest distance between a WMS position and a detected bin centre that still matches, metres;
        about half a bay width keeps neighbouring bins apart. Id matches further apart are discrepancies.
    match_by : MatchBy
        Equal ids first (default), or positions first.

    Returns
    -------
    Reconciliation
        Matches (sorted by WMS id), WMS ids missing in the map, detected ids unknown to the WMS, the id matches
        further than ``tolerance_m`` from their WMS position and what those say about the numbering.
    """
    if not tolerance_m > 0:
        raise ValueError(f"tolerance_m must be positive, got {tolerance_m}")
    detected_ids = {d.id for d in detected}
    by_id = {d.id: d for d in detected}
    by_id_first = [w for w in wms if match_by == MatchBy.ID or w.x_m is None or w.y_m is None]
    matches = [Match(w.wms_id, w.wms_id, "id", _distance(w, by_id[w.wms_id])) for w in by_id_first
               if w.wms_id in by_id]
    taken_wms = {m.wms_id for m in matches}
    taken_detected = {m.detected_id for m in matches}
    free_detected = [d for d in detected if d.id not in taken_detected]
    positioned = [w for w in wms if w.wms_id not in taken_wms and w.x_m is not None and w.y_m is not None]
    if free_detected and positioned:
        matches.extend(_by_position(positioned, free_detected, tolerance_m))
    matched_wms = {m.wms_id for m in matches}
    matched_detected = {m.detected_id for m in matches}
    discrepancies = _discrepancies(wms, detected, matches, tolerance_m)
    return Reconciliation(
        matched=sorted(matches, key=lambda m: m.wms_id),
        missing_in_map=sorted(w.wms_id for w in wms if w.wms_id not in matched_wms),
        unknown_to_wms=sorted(detected_ids - matched_detected),
        discrepancies=discrepancies,
        numbering=check_numbering(matches, discrepancies, wms, detected, tolerance_m=tolerance_m),
    )


def _discrepancies(wms: Sequence[WmsBin], detected: Sequence[DetectedBin], matches: Sequence[Match],
                   tolerance_m: float) -> list[Discrepancy]:
    """Id matches further than ``tolerance_m`` from their WMS position, furthest first, each with the detected bin
    nearest its WMS position (on the WMS id's level first) within the tolerance."""
    far = [m for m in matches if m.by == "id" and m.distance_m is not None and m.distance_m > tolerance_m]
    if not far:
        return []
    wms_of = {w.wms_id: w for w in wms}
    by_id = {d.id: d for d in detected}
    tree = cKDTree(np.array([(d.x_m, d.y_m) for d in detected], dtype=float))
    out = []
    for match in far:
        w, d = wms_of[match.wms_id], by_id[match.detected_id]
        x, y = w.x_m or 0.0, w.y_m or 0.0  # a far match has a WMS position
        near = [detected[k] for k in tree.query_ball_point((x, y), tolerance_m)]
        near.sort(key=lambda n: (_level_of(n.id) != _level_of(w.wms_id), np.hypot(n.x_m - x, n.y_m - y)))
        out.append(Discrepancy(w.wms_id, (x, y), (d.x_m, d.y_m), float(match.distance_m or 0.0),
                               near[0].id if near else None))
    return sorted(out, key=lambda item: (-item.distance_m, item.wms_id))


def _numbers(bin_id: str) -> tuple[int, int, int] | None:
    """(aisle, bay, level + 1 or 0) of an id in Aisle's scheme, else None."""
    found = _AISLE_ID.fullmatch(bin_id)
    if found is None:
        return None
    return int(found[1]), int(found[2]), int(found[3] or 0)


def _level_of(bin_id: str) -> int | None:
    numbers = _numbers(bin_id)
    return None if numbers is None else numbers[2]


def check_numbering(matches: Sequence[Match], discrepancies: Sequence[Discrepancy], wms: Sequence[WmsBin],
                    detected: Sequence[DetectedBin], *, tolerance_m: float) -> NumberingCheck:
    """What the positions of the bins matched by id say about the site's numbering (:class:`Verdict`).

    Most (more than half) id matches far off means the ids do not name the same bins on both sides: the
    commonest id shift (from the WMS id to the id of the detected bin at the WMS position) or the median
    position offset is reported, with how many bins it explains, and the verdict names the one that explains
    most of them (at least half).
    """
    positioned = [m for m in matches if m.by == "id" and m.distance_m is not None]
    far = len(discrepancies)
    if not positioned:
        return NumberingCheck(Verdict.UNCHECKED, 0, 0, None, None, 0, None,
                              "no bin matched by id has a WMS position, so the numbering could not be checked")
    wms_of = {w.wms_id: w for w in wms}
    by_id = {d.id: d for d in detected}
    delta = np.array([(by_id[m.detected_id].x_m - (wms_of[m.wms_id].x_m or 0.0),
                       by_id[m.detected_id].y_m - (wms_of[m.wms_id].y_m or 0.0)) for m in positioned])
    median = float(np.median(np.hypot(delta[:, 0], delta[:, 1])))
    offset = np.median(delta, axis=0)
    offset_support = int((np.hypot(*(delta - offset).T) <= tolerance_m).sum())
    shifts = Counter(
        tuple(int(a - b) for a, b in zip(after, before, strict=True))
        for item in discrepancies if item.nearest_detected_id is not None
        and (after := _numbers(item.nearest_detected_id)) is not None and (before := _numbers(item.wms_id)) is not None)
    shift = None
    if shifts:
        (aisle, bay, level), support = shifts.most_common(1)[0]
        shift = IdShift(aisle, bay, level, support)
    offset_xy = (float(offset[0]), float(offset[1]))
    verdict = _verdict(len(positioned), far, shift, offset_xy, offset_support, tolerance_m)
    return NumberingCheck(verdict, len(positioned), far, median, offset_xy, offset_support, shift,
                          _message(verdict, len(positioned), far, median, shift, offset_xy, offset_support,
                                   tolerance_m))


def _verdict(count: int, far: int, shift: IdShift | None, offset: XY, offset_support: int, tolerance_m: float
             ) -> Verdict:
    if far == 0:
        return Verdict.CONSISTENT
    if 2 * far <= count:
        return Verdict.SOME_FAR
    if shift is not None and 2 * shift.support >= far:
        return Verdict.RENUMBERED
    if np.hypot(*offset) > tolerance_m and 2 * offset_support >= count:
        return Verdict.SHIFTED
    return Verdict.INCONSISTENT


def _message(verdict: Verdict, count: int, far: int, median: float, shift: IdShift | None, offset: XY,
             offset_support: int, tolerance_m: float) -> str:
    head = (f"{far} of {count} bins matched by id lie further than {tolerance_m:g} m from their WMS position "
            f"(median distance {median:.2f} m)")
    if verdict == Verdict.CONSISTENT:
        return f"all {count} bins matched by id lie within {tolerance_m:g} m of their WMS position"
    if verdict == Verdict.SOME_FAR:
        return f"{head}; see the discrepancies"
    if verdict == Verdict.RENUMBERED and shift is not None:
        return (f"{head}: the site numbers bins differently from Aisle's scheme; at {shift.support} of them the "
                f"detected bin has the WMS id shifted by aisle {shift.aisle:+d}, bay {shift.bay:+d}, level "
                f"{shift.level:+d}. Import the list with match_by=position to match these bins by position")
    if verdict == Verdict.SHIFTED:
        return (f"{head}: {offset_support} of them agree once the detected bins are moved by ({-offset[0]:+.2f}, "
                f"{-offset[1]:+.2f}) m; the WMS positions look like another frame than the map's")
    return f"{head}, with no common shift of ids or offset of positions; check the ids and the survey"


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
    match_by: MatchBy
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
    by = imported.summary.get("match_by", MatchBy.ID.value)
    match_by = MatchBy(by) if by in tuple(MatchBy) else MatchBy.ID
    detected = [detected_bin(Bin.from_feature(item.feature))
                for item in store.features(map_id, kinds=[FeatureKind.BIN], revision=revision)]
    result = reconcile(store.wms_bins(map_id, revision=revision), detected, tolerance_m=tolerance_m,
                       match_by=match_by)
    return WmsMatching(result, tolerance_m, match_by, imported.id)
