"""Place labels of faces: geometric and template evidence, categories mapped to labels by vote."""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.faces import FaceGeometry
from services.grid_decomposition.templates import template_branches
from shared.vocabulary import PlaceLabel


class FaceLabels(NamedTuple):
    """Labels of faces, index 0 unused.

    Attributes
    ----------
    evidence : (F + 1,) int64
        :class:`PlaceLabel` value each face gets from geometry and the templates alone.
    category : (F + 1,) int64
        Place category by vote of the face's samples, -1 where it has none.
    label : (F + 1,) int64
        Final :class:`PlaceLabel` value.
    category_labels : dict
        The category -> label assignment used (automatic, then overridden by a person).
    """

    evidence: npt.NDArray[np.int64]
    category: npt.NDArray[np.int64]
    label: npt.NDArray[np.int64]
    category_labels: dict[int, PlaceLabel]


class Evidence(NamedTuple):
    """What geometry and the templates say of each face, index 0 unused.

    Attributes
    ----------
    label : (F + 1,) int64
        :class:`PlaceLabel` value.
    off_pitch : (F + 1,) bool
        Bay-shaped faces between uprights left out of storage because they are longer than the
        bays around them (a cross aisle one bay wide); they are drivable in ``label``.
    """

    label: npt.NDArray[np.int64]
    off_pitch: npt.NDArray[np.bool_]


def face_categories(
    face_image: npt.NDArray[np.int32],
    n_faces: int,
    rows: npt.NDArray[np.int64],
    cols: npt.NDArray[np.int64],
    category: npt.NDArray[np.int64],
    n_categories: int,
) -> npt.NDArray[np.int64]:
    """Category of each face as the statistical mode of its samples' categories (-1 without any)."""
    faces = face_image[rows, cols].astype(np.int64)
    votes = np.zeros((n_faces + 1, max(n_categories, 1)), dtype=np.int64)
    np.add.at(votes, (faces, category), 1)
    out: npt.NDArray[np.int64] = np.argmax(votes, axis=1).astype(np.int64)
    out[votes.sum(axis=1) == 0] = -1
    out[0] = -1
    return out


def evidence_labels(
    links: npt.NDArray[np.int64],
    geometry: FaceGeometry,
    component: npt.NDArray[np.int64],
    component_elongation: npt.NDArray[np.float64],
    face_free_px: npt.NDArray[np.int64],
    *,
    resolution_m: float,
    storage_max_depth_m: float = 1.6,
    storage_max_width_m: float = 3.0,
    storage_min_width_m: float = 1.8,
    storage_max_walled: float = 0.3,
    max_pitch_ratio: float = 1.08,
    corridor_max_width_m: float = 4.0,
    corridor_min_elongation: float = 4.0,
    open_area_min_m2: float = 150.0,
) -> Evidence:
    """Label evidence per face from its geometry and the paper-B templates.

    Storage: a small rectangle (short side <= ``storage_max_depth_m``, long side <=
    ``storage_max_width_m`` and >= ``storage_min_width_m``: a bay) with at least three corners
    on obstacles (uprights), an outline mostly open (at most ``storage_max_walled`` of it
    touching obstacles), not both short sides ending on obstacles in their middle (a slice of a
    corridor between two lines ends on its walls; a bay's short sides run between uprights) and
    at most ``max_pitch_ratio`` times as long as the median bay of its
    connected component (bays of a rack share a pitch: a cross aisle one bay wide, 3.0 m in 2.7 m
    racks, is no bay); a bay with missing uprights is storage when at least two storage faces
    neighbour it (three if fewer than two of its corners are on obstacles): it lies in a rack row;
    a strip too thin for the short-side test (a flue) is storage next to one storage face. Faces of a compact
    connected component (elongation below ``corridor_min_elongation`` and no storage) are one
    room (or open area above ``open_area_min_m2``). In the other components (networks of
    aisles or corridors) the templates run on the graph of non-storage faces: T/X junctions, and
    corridor pieces (two branches or a dead end, short side <= ``corridor_max_width_m``); a small
    cluster of faces matching no template that matches the T or X template as one node (a widened
    crossing) is a junction; the rest is open area.

    Parameters
    ----------
    links : (L, 2) int64
        Connected (non-cogent) links between faces, ids 1..F.
    """
    n = geometry.short_m.size
    ev = np.full(n, PlaceLabel.NONE.value, dtype=np.int64)
    is_free = face_free_px > 0
    bay = (
        is_free
        & (geometry.short_m <= storage_max_depth_m)
        & (geometry.long_m <= storage_max_width_m)
        & (geometry.long_m >= storage_min_width_m)
        & (geometry.walled_fraction <= storage_max_walled)
        & (geometry.ends_on_obstacle < 2)
    )
    pitch = _pitch(geometry.long_m, component, bay & (geometry.corners_on_obstacle >= 3))
    off_pitch = bay & (geometry.corners_on_obstacle >= 3) & (geometry.long_m > max_pitch_ratio * pitch)
    bay &= ~off_pitch
    storage = bay & (geometry.corners_on_obstacle >= 3) & (geometry.ends_on_obstacle >= 0)
    # a strip too thin to tell a bay from a slice of a corridor (a flue between back-to-back racks)
    # is storage next to one storage face, a bay with missing uprights in a rack row next to two
    # (three when fewer than two of its corners stand on uprights)
    weak = bay & ~storage
    need = np.select(
        [geometry.corners_on_obstacle >= 3, geometry.corners_on_obstacle == 2], [1, 2], default=3
    )
    e_all = np.asarray(links, dtype=np.int64).reshape(-1, 2)
    for _ in range(3):
        nb = np.bincount(e_all[:, 0], weights=storage[e_all[:, 1]], minlength=n)
        nb += np.bincount(e_all[:, 1], weights=storage[e_all[:, 0]], minlength=n)
        grown = weak & ~storage & (nb >= need)
        if not grown.any():
            break
        storage |= grown
    ev[storage] = PlaceLabel.STORAGE.value
    has_storage = np.zeros(component_elongation.size, dtype=bool)
    has_storage[component[storage]] = True
    area_m2 = np.bincount(component, weights=face_free_px, minlength=has_storage.size) * resolution_m**2
    network = has_storage | (component_elongation >= corridor_min_elongation)
    compact = is_free & ~storage & ~network[component]
    ev[compact] = np.where(area_m2[component[compact]] >= open_area_min_m2, PlaceLabel.OPEN_AREA, PlaceLabel.ROOM)
    drivable = is_free & ~storage & network[component]
    e = np.asarray(links, dtype=np.int64).reshape(-1, 2)
    e = e[drivable[e[:, 0]] & drivable[e[:, 1]]]
    branches = template_branches(n, e)
    junction = drivable & (branches >= 3) & (branches <= 4)
    corridor = drivable & (branches >= 1) & (branches <= 2) & (geometry.short_m <= corridor_max_width_m)
    junction |= _cluster_junctions(
        e,
        drivable & ~junction & ~corridor,
        face_free_px.astype(np.float64) * resolution_m**2,
        max_area_m2=corridor_max_width_m**2,
    )
    ev[drivable] = PlaceLabel.OPEN_AREA.value
    ev[junction] = PlaceLabel.JUNCTION.value
    ev[corridor] = PlaceLabel.CORRIDOR.value
    return Evidence(ev, off_pitch)


def _pitch(
    long_m: npt.NDArray[np.float64], component: npt.NDArray[np.int64], bay: npt.NDArray[np.bool_]
) -> npt.NDArray[np.float64]:
    """Per face, the median long side of the bays in its connected component (inf where there are none)."""
    median = np.full(int(component.max()) + 1, np.inf)
    for c in np.unique(component[bay]):
        median[c] = float(np.median(long_m[bay & (component == c)]))
    out: npt.NDArray[np.float64] = median[component]
    return out


def _cluster_junctions(
    links: npt.NDArray[np.int64], rest: npt.NDArray[np.bool_], area_m2: npt.NDArray[np.float64], *, max_area_m2: float
) -> npt.NDArray[np.bool_]:
    """Faces of small clusters of unmatched drivable faces that, taken as one node, match the T or X template.

    A crossing widened into a small square is cut by its own edges into several faces, none of
    which matches a template alone; contracted into one node of at most ``max_area_m2`` it does.
    """
    n = rest.size
    inner = links[rest[links[:, 0]] & rest[links[:, 1]]]
    graph = coo_matrix((np.ones(len(inner)), (inner[:, 0], inner[:, 1])), shape=(n, n))
    _, cluster = connected_components(graph, directed=False)
    node = np.where(rest, n + cluster, np.arange(n))
    branches = template_branches(2 * n, node[links])
    cluster_area = np.bincount(cluster[rest], weights=area_m2[rest], minlength=n)
    small = cluster_area <= max_area_m2
    matches = (branches[n:] >= 3) & (branches[n:] <= 4) & small
    out: npt.NDArray[np.bool_] = rest & matches[cluster]
    return out


def assign_labels(
    evidence: npt.NDArray[np.int64],
    category: npt.NDArray[np.int64],
    face_free_px: npt.NDArray[np.int64],
    *,
    overrides: Mapping[int, PlaceLabel] | None = None,
    min_purity: float = 0.9,
) -> FaceLabels:
    """Map place categories to labels and label faces.

    Each category gets the label most of its faces' free area has as evidence (its purity is
    that share); ``overrides`` (category -> label, a person's choice) replace the automatic
    assignment. A face takes its category's label when the category was overridden, or when the
    category is at least ``min_purity`` pure and the face has no decisive evidence of its own (a
    pallet-cell rectangle or a corridor or junction template; the ray-cast shape of a cross-aisle
    piece between two rack ends and that of a pallet cell can coincide). Otherwise (mixed
    categories, no category, decisive evidence) it keeps its own evidence.
    """
    n_cat = int(category.max()) + 1 if category.size else 0
    votes = np.zeros((max(n_cat, 1), len(PlaceLabel)), dtype=np.float64)
    has = category >= 0
    np.add.at(votes, (category[has], evidence[has]), face_free_px[has].astype(np.float64))
    votes[:, PlaceLabel.NONE.value] = 0.0
    total = votes.sum(axis=1)
    purity = np.divide(votes.max(axis=1), total, out=np.zeros_like(total), where=total > 0)
    mapping: dict[int, PlaceLabel] = {}
    for c in range(n_cat):
        mapping[c] = PlaceLabel(int(np.argmax(votes[c]))) if total[c] > 0 else PlaceLabel.UNIDENTIFIED
    trusted = purity >= min_purity
    for c, label in (overrides or {}).items():
        mapping[c] = label
    lut = np.array([mapping.get(c, PlaceLabel.UNIDENTIFIED).value for c in range(max(n_cat, 1))], dtype=np.int64)
    decisive = np.isin(evidence, [PlaceLabel.STORAGE.value, PlaceLabel.CORRIDOR.value, PlaceLabel.JUNCTION.value])
    overridden = np.zeros(trusted.size, dtype=bool)
    overridden[[c for c in (overrides or {}) if 0 <= c < trusted.size]] = True
    cat = np.maximum(category, 0)
    use = has & (overridden[cat] | (trusted[cat] & ~decisive))
    final = np.where(use, lut[np.maximum(category, 0)], evidence).astype(np.int64)
    final[(final == PlaceLabel.NONE.value) & (face_free_px > 0)] = PlaceLabel.UNIDENTIFIED.value
    final[face_free_px == 0] = PlaceLabel.NONE.value
    return FaceLabels(evidence, category, final, mapping)
