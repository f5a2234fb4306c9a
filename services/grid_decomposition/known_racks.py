"""Racks another stage knows (the pillar stage's), as places the decomposition takes for granted.

The pillar stage maps the uprights themselves and writes each rack row (``rack_row``), its pallet cells (``bin``
features with their footprints) and the aisle between facing rows (``corridor`` features keyed ``aisle-NN``); where
it has, it is the authority. Its bin footprints are storage and its aisles corridors, each end of an aisle and
each cross aisle it runs through a junction (:func:`known_layout`), whatever the occupancy grid shows of the racks
(a lidar below the beams sees a few uprights, or nothing).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.pipeline import Decomposition
from services.grid_decomposition.racks import RackLayout
from shared.store import Feature, GridLayer, MapStore, Revision
from shared.vocabulary import FeatureKind, PlaceLabel

KNOWN_RACKS_STAGE = "pillar_mapping"
"""The stage whose rack rows and bins are the authority on racks."""

Footprint = npt.NDArray[np.float64]
"""(K, 2) corners of a polygon, map metres."""
_SHIFT = 4  # fractional bits of the polygon corners given to cv2.fillPoly
_JITTER_M = 0.05  # footprints that moved less than this (a grid cell) are the same


def footprints(features: Sequence[Feature], kind: str) -> list[Footprint]:
    """The outer rings (K, 2) of the Polygon features of ``kind``, each shape once (bins on several levels share
    one footprint; rounded to a millimetre to tell them apart), in order of their centres on a 0.5 m grid (y,
    then x), so the same places read twice come in the same order."""
    out: dict[bytes, Footprint] = {}
    for item in features:
        geometry = item.geometry
        if item.kind != kind or geometry.get("type") != "Polygon" or not geometry.get("coordinates"):
            continue
        ring = np.asarray(geometry["coordinates"][0], dtype=np.float64).reshape(-1, 2)
        if len(ring) >= 3:  # the store keeps coordinates finite
            out.setdefault(np.round(ring, 3).tobytes(), ring)
    return sorted(out.values(), key=lambda ring: (*np.round(ring.mean(axis=0)[::-1] * 2).tolist(), ring.tobytes()))


def _pixels(ring: Footprint, resolution_m: float, origin_xy_m: tuple[float, float]) -> npt.NDArray[np.int32]:
    return np.round((ring - origin_xy_m) * (float(1 << _SHIFT) / resolution_m) - 0.5 * (1 << _SHIFT)).astype(np.int32)


def _frame(aisle: Footprint) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float, float, float, bool]:
    """An aisle rectangle's centre (2,), unit axis along it (2,), length and width (metres), the angle of its
    minimum-area rectangle (degrees) and whether that rectangle's first side runs along the axis."""
    (cx, cy), (w, h), angle_deg = cv2.minAreaRect(np.asarray(aisle, dtype=np.float32).reshape(-1, 2))
    turn = np.radians(angle_deg) + (0.0 if w >= h else np.pi / 2)
    return np.array([cx, cy]), np.array([np.cos(turn), np.sin(turn)]), max(w, h), min(w, h), angle_deg, w >= h


def _box(centre: npt.NDArray[np.float64], along: float, across: float, angle_deg: float, *, wide: bool
         ) -> Footprint:
    """Corners (4, 2) of a rectangle ``along`` x ``across`` metres turned like the aisle (``wide``: its long side
    along the aisle's axis)."""
    size = (along, across) if wide else (across, along)
    out: Footprint = cv2.boxPoints(((float(centre[0]), float(centre[1])), size, angle_deg)).astype(np.float64)
    return out


def aisle_ends(aisle: Footprint) -> list[Footprint]:
    """The two squares (as wide as the aisle) beyond the ends of an aisle's rectangle: where it meets a cross
    aisle or the perimeter aisle, a junction."""
    centre, axis, length, width, angle_deg, _ = _frame(aisle)
    return [_box(centre + side * (length + width) / 2 * axis, width, width, angle_deg, wide=True)
            for side in (-1.0, 1.0)]


def _facing(aisle: Footprint, bins: Sequence[Footprint]) -> dict[float, tuple[list[tuple[float, float]], float]]:
    """Per side of an aisle (-1, +1 across it) with bins facing it: their stretches along it (metres from its
    centre) and how far from its centre line their backs reach."""
    centre, axis, length, width, _, _ = _frame(aisle)
    normal = np.array([-axis[1], axis[0]])
    out: dict[float, tuple[list[tuple[float, float]], float]] = {}
    for ring in bins:
        rel = np.asarray(ring, dtype=np.float64).reshape(-1, 2) - centre
        u, v = rel @ axis, rel @ normal
        facing = abs(np.abs(v).min() - width / 2) <= 0.25 * width and np.ptp(np.sign(v)) == 0
        if facing and u.max() > -length / 2 and u.min() < length / 2:
            spans, depth = out.get(float(np.sign(v.mean())), ([], 0.0))
            spans.append((float(u.min()), float(u.max())))
            out[float(np.sign(v.mean()))] = (spans, max(depth, float(np.abs(v).max())))
    return out


def aisle_crossings(aisle: Footprint, bins: Sequence[Footprint], *, min_gap_m: float = 0.5
                    ) -> list[tuple[float, float]]:
    """Stretches (start, end; metres along the aisle from its centre) where no bin faces the aisle on either side:
    a cross aisle through the racks (an aisle the pillar stage spans from its first bin to its last runs through
    the cross aisles between its sections). A side with no bin at all does not count; stretches shorter than
    ``min_gap_m`` are no crossing (neighbouring bins share their uprights)."""
    length = _frame(aisle)[2]
    sides = [sorted(spans) for spans, _ in _facing(aisle, bins).values()]
    if not sides:
        return []
    edges = np.unique(np.concatenate([[-length / 2, length / 2], *(np.ravel(spans) for spans in sides)]))
    edges = edges[(edges >= -length / 2) & (edges <= length / 2)]
    middle = (edges[:-1] + edges[1:]) / 2
    open_ = np.ones(middle.size, dtype=bool)
    for spans in sides:
        lo, hi = np.array(spans).T
        open_ &= ~((middle[:, None] >= lo) & (middle[:, None] <= hi)).any(axis=1)
    out: list[tuple[float, float]] = []
    for k in np.flatnonzero(open_):
        if out and np.isclose(out[-1][1], edges[k]):
            out[-1] = (out[-1][0], float(edges[k + 1]))
        else:
            out.append((float(edges[k]), float(edges[k + 1])))
    return [(a, b) for a, b in out if b - a >= min_gap_m and -length / 2 < a and b < length / 2]


def _aisle_pieces(aisle: Footprint, bins: Sequence[Footprint], *, flue_m: float = 0.15
                  ) -> tuple[list[Footprint], list[Footprint], list[Footprint]]:
    """An aisle cut at its crossings (:func:`aisle_crossings`): its corridor pieces, its crossings, and the
    cross-aisle pieces beside each crossing and each end square (:func:`aisle_ends`) through the racks on either
    side, as deep as the bins there reach plus ``flue_m`` (a back-to-back row's flue)."""
    crossings = aisle_crossings(aisle, bins)
    centre, axis, length, width, angle_deg, wide = _frame(aisle)
    normal = np.array([-axis[1], axis[0]])
    cuts = [-length / 2, *np.ravel(crossings), length / 2]
    pieces = [(a, b) for a, b in zip(cuts[0::2], cuts[1::2], strict=True) if b > a]
    aisle_boxes = [aisle] if not crossings else [
        _box(centre + (a + b) / 2 * axis, b - a, width, angle_deg, wide=wide) for a, b in pieces]
    crossing_boxes = [_box(centre + (a + b) / 2 * axis, b - a, width, angle_deg, wide=wide) for a, b in crossings]
    beside = []
    for side, (_, depth) in _facing(aisle, bins).items():
        across = depth + flue_m - width / 2
        offset = side * (width / 2 + across / 2) * normal
        for a, b in [(-length / 2 - width, -length / 2), *crossings, (length / 2, length / 2 + width)]:
            beside.append(_box(centre + (a + b) / 2 * axis + offset, b - a, across, angle_deg, wide=wide))
    return aisle_boxes, crossing_boxes, beside


def known_layout(
    bins: Sequence[Footprint],
    aisles: Sequence[Footprint],
    *,
    shape: tuple[int, int],
    resolution_m: float,
    origin_xy_m: tuple[float, float],
) -> RackLayout:
    """A :class:`~services.grid_decomposition.racks.RackLayout` of known places on a grid (row 0 = lowest y):
    every bin footprint a storage place, every aisle a corridor place and each end of it a junction
    (:func:`aisle_ends`; a bin wins over an aisle, an aisle over a junction, where they overlap). An aisle that
    runs through a cross aisle (no bin faces it there on either side, :func:`aisle_crossings`) is a junction
    there and a corridor place on each side of it; beside each end square and crossing, the cross aisle through
    the racks on either side is a corridor place (a pallet left at the racks' end is no rack).

    Parameters
    ----------
    bins, aisles : sequence of (K, 2) float64
        Polygons in map metres.
    shape, resolution_m, origin_xy_m
        The grid.
    """
    if resolution_m <= 0:
        raise DecompositionError(f"resolution_m must be positive, got {resolution_m}")
    cells = np.zeros(shape, dtype=np.int32)
    labels = [0]
    cut = [_aisle_pieces(aisle, bins) for aisle in aisles]
    junctions = [end for aisle in aisles for end in aisle_ends(aisle)] + [box for _, boxes, _ in cut for box in boxes]
    corridors = [box for boxes, _, beside in cut for box in boxes + beside]
    for polygons, label in ((junctions, PlaceLabel.JUNCTION), (corridors, PlaceLabel.CORRIDOR),
                            (bins, PlaceLabel.STORAGE)):
        for ring in polygons:
            labels.append(label.value)
            cv2.fillPoly(cells, [_pixels(ring, resolution_m, origin_xy_m)], len(labels) - 1, cv2.LINE_8, _SHIFT)
    present = np.zeros(len(labels), dtype=bool)
    present[np.unique(cells)] = True
    lut = np.cumsum(present) - 1  # places that cover no cell centre are dropped, ids 1..N again
    cells = np.where(cells > 0, lut[cells], 0).astype(np.int32)
    cell_labels = np.concatenate([[0], np.asarray(labels, dtype=np.int64)[present][1:]])
    outline = np.zeros(shape, dtype=bool)
    outline[:, 1:] |= cells[:, 1:] != cells[:, :-1]
    outline[1:, :] |= cells[1:, :] != cells[:-1, :]
    return RackLayout(cells, cell_labels, outline, np.zeros((0, 4, 2), np.float64))


def footprint_mask(
    footprints: Sequence[Footprint],
    *,
    shape: tuple[int, int],
    resolution_m: float,
    origin_xy_m: tuple[float, float],
) -> npt.NDArray[np.bool_]:
    """(H, W) bool: cells of a grid (row 0 = lowest y) whose centres the footprints cover."""
    if resolution_m <= 0:
        raise DecompositionError(f"resolution_m must be positive, got {resolution_m}")
    covered = np.zeros(shape, dtype=np.uint8)
    if footprints:
        cv2.fillPoly(covered, [_pixels(np.asarray(f, dtype=np.float64), resolution_m, origin_xy_m) for f in footprints],
                     1, cv2.LINE_8, _SHIFT)
    mask: npt.NDArray[np.bool_] = covered > 0
    return mask


def aisle_regions(decomposition: Decomposition, aisles: Sequence[tuple[str, Footprint]]) -> dict[int, str]:
    """Region id -> aisle key: for each aisle (key, outline in map metres), the corridor regions that are the strip
    between its facing rows: each holding more than half of the aisle's region cells, or lying more than half
    inside it (an aisle cut by a cross aisle is a corridor region on each side of the crossing)."""
    segments = decomposition.segments
    sizes = np.bincount(segments.ravel())
    out: dict[int, str] = {}
    for key, ring in aisles:
        inside = footprint_mask([ring], shape=segments.shape, resolution_m=decomposition.resolution_m,
                                origin_xy_m=decomposition.origin_xy_m) & (segments > 0)
        ids, counts = np.unique(segments[inside], return_counts=True)
        mine = (2 * counts > counts.sum()) | (2 * counts > sizes[ids])
        for rid in ids[mine].tolist():
            if decomposition.regions[rid].label is PlaceLabel.CORRIDOR and rid not in out:
                out[rid] = key
    return out


class KnownRacks:
    """The pillar stage's bin and aisle footprints for a worker: read from the store at first and again whenever a
    revision of that stage changed its bins or aisles (:meth:`note`), so a decomposition costs no feature read."""

    def __init__(self) -> None:
        self.bins: list[Footprint] = []
        self.aisles: list[Footprint] = []
        self.aisle_keys: list[str] = []
        self._stale = True

    def note(self, revisions: Sequence[Revision]) -> bool:
        """Look at newly stored revisions; whether one of the pillar stage's changed its bins or aisles."""
        for revision in revisions:
            changes = revision.summary.get("features", {})
            if revision.stage == KNOWN_RACKS_STAGE and isinstance(changes, dict) and any(
                    isinstance(change := changes.get(kind), dict) and any(
                        change.get(what) for what in ("added", "removed", "moved"))
                    for kind in (FeatureKind.BIN, FeatureKind.CORRIDOR)):
                self._stale = True
        return self._stale

    def refresh(self, store: MapStore, map_id: int) -> bool:
        """Re-read the footprints if a change was noted; whether they differ by more than ``_JITTER_M`` (a
        refit moves every bin a little each time; that is no reason to decompose again)."""
        if not self._stale:
            return False
        read = [s.feature for s in store.features(map_id, kinds=[FeatureKind.BIN, FeatureKind.CORRIDOR])
                if s.stage == KNOWN_RACKS_STAGE]
        keyed = sorted((f.key, ring) for f in read for ring in footprints([f], FeatureKind.CORRIDOR))
        found = (footprints(read, FeatureKind.BIN), [ring for _, ring in keyed])
        self._stale = False
        same = all(len(new) == len(old) and all(
            a.shape == b.shape and np.allclose(a, b, atol=_JITTER_M) for a, b in zip(new, old, strict=True))
            for new, old in zip(found, (self.bins, self.aisles), strict=True))
        self.bins, self.aisles = found
        self.aisle_keys = [key for key, _ in keyed]
        return not same

    def names(self, decomposition: Decomposition) -> dict[int, str]:
        """Region id -> key of the aisle it is (:func:`aisle_regions`)."""
        return aisle_regions(decomposition, list(zip(self.aisle_keys, self.aisles, strict=True)))

    def on_grid(self, layer: GridLayer) -> RackLayout | None:
        """The known places on the grid of ``layer`` (:func:`known_layout`); None while there are no bins."""
        if not self.bins:
            return None
        return known_layout(self.bins, self.aisles, shape=layer.data.shape, resolution_m=layer.resolution_m,
                            origin_xy_m=(layer.origin_x_m, layer.origin_y_m))
