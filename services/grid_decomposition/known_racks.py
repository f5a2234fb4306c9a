"""Racks another stage knows (the pillar stage's), as places the decomposition takes for granted.

The pillar stage maps the uprights themselves and writes each rack row (``rack_row``), its pallet cells (``bin``
features with their footprints) and the aisle between facing rows (``corridor`` features keyed ``aisle-NN``); where
it has, it is the authority. Its bin footprints are storage and its aisles corridors
(:func:`known_layout`), whatever the occupancy grid shows of the racks (a lidar below the beams sees a few
uprights, or nothing).
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


def aisle_ends(aisle: Footprint) -> list[Footprint]:
    """The two squares (as wide as the aisle) beyond the ends of an aisle's rectangle: where it meets a cross
    aisle or the perimeter aisle, a junction."""
    (cx, cy), (w, h), angle_deg = cv2.minAreaRect(np.asarray(aisle, dtype=np.float32).reshape(-1, 2))
    length, width = max(w, h), min(w, h)
    turn = np.radians(angle_deg) + (0.0 if w >= h else np.pi / 2)
    axis = np.array([np.cos(turn), np.sin(turn)])
    out = []
    for side in (-1.0, 1.0):
        centre = np.array([cx, cy]) + side * (length + width) / 2 * axis
        out.append(cv2.boxPoints(((float(centre[0]), float(centre[1])), (width, width), angle_deg)).astype(np.float64))
    return out


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
    (:func:`aisle_ends`; a bin wins over an aisle, an aisle over a junction, where they overlap).

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
    ends = [end for aisle in aisles for end in aisle_ends(aisle)]
    for polygons, label in ((ends, PlaceLabel.JUNCTION), (aisles, PlaceLabel.CORRIDOR), (bins, PlaceLabel.STORAGE)):
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
    """Region id -> aisle key: for each aisle (key, outline in map metres), the corridor region holding more than
    half of the aisle's region cells, if one does (the strip between two facing rows is that aisle)."""
    segments = decomposition.segments
    out: dict[int, str] = {}
    for key, ring in aisles:
        inside = footprint_mask([ring], shape=segments.shape, resolution_m=decomposition.resolution_m,
                                origin_xy_m=decomposition.origin_xy_m) & (segments > 0)
        ids, counts = np.unique(segments[inside], return_counts=True)
        if counts.size and 2 * counts.max() > counts.sum():
            rid = int(ids[counts.argmax()])
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
