"""Regions: faces merged into room, corridor, junction and storage instances, and their topology."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.arrays import lookup
from services.grid_decomposition.cogency import EdgeCogency
from services.grid_decomposition.segments import border_closure
from services.grid_decomposition.semantics import link_connection
from services.grid_decomposition.subdivision import Subdivision
from shared.vocabulary import PlaceLabel

if TYPE_CHECKING:
    import networkx as nx


def link_components(n_nodes: int, links: npt.NDArray[np.int64], keep: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    """Connected-component id (1-based) of every node over ``links`` (L, 2); 0 where ``keep`` is False."""
    ok = keep[links[:, 0]] & keep[links[:, 1]] if links.size else np.zeros(0, dtype=bool)
    e = links[ok]
    m = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_nodes, n_nodes))
    _, comp = connected_components(m, directed=False)
    _, dense = np.unique(comp, return_inverse=True)
    return np.where(keep, dense + 1, 0).astype(np.int64)


def warehouse_floors(
    component: npt.NDArray[np.int64],
    face_free_px: npt.NDArray[np.int64],
    face_label: npt.NDArray[np.int64],
    *,
    min_storage_share: float = 0.15,
    min_storage_faces: int = 12,
    min_storage_face_share: float = 0.3,
) -> npt.NDArray[np.bool_]:
    """Per component id: a warehouse floor, with at least ``min_storage_faces`` storage faces making up
    at least ``min_storage_share`` of its free area and ``min_storage_face_share`` of its faces.

    Pallet cells come in long rows, about every other face of a warehouse floor (half of them in
    the synthetic warehouses); storage-like faces between furniture are a few, or a small share
    of a room's many faces, and do not make a room a floor.

    Parameters
    ----------
    component : (F + 1,) int64
        Component id per face (0 = none), from :func:`link_components`.
    face_free_px : (F + 1,) int64
    face_label : (F + 1,) int64
        :class:`PlaceLabel` value per face.

    Returns
    -------
    (C,) bool
        Indexed by component id; False for 0.
    """
    n_comp = int(component.max()) + 1
    area = np.bincount(component, weights=face_free_px, minlength=n_comp)
    stored = np.bincount(component, weights=face_free_px * (face_label == PlaceLabel.STORAGE.value), minlength=n_comp)
    cells = np.bincount(component, weights=face_label == PlaceLabel.STORAGE.value, minlength=n_comp)
    faces = np.bincount(component, weights=face_free_px > 0, minlength=n_comp)
    floor: npt.NDArray[np.bool_] = (
        (stored >= min_storage_share * np.maximum(area, 1))
        & (cells >= min_storage_faces)
        & (cells >= min_storage_face_share * faces)
    )
    floor[0] = False
    return floor


def road_networks(
    sub: Subdivision,
    cogency: EdgeCogency,
    component: npt.NDArray[np.int64],
    face_free_px: npt.NDArray[np.int64],
    face_label: npt.NDArray[np.int64],
    *,
    min_road_share: float = 0.95,
    free: npt.NDArray[np.bool_] | None = None,
    occupied: npt.NDArray[np.bool_] | None = None,
    known: npt.NDArray[np.bool_] | None = None,
    rays: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.bool_]:
    """Per component id: a network of roads, at least ``min_road_share`` of its free area corridor
    and junction faces, with at least one junction and no closed doorway on its edges.

    A grid of passages between solid blocks (the tuw warehouses) is one such component; split into
    corridors and junctions it gets a topology. An office corridor network has doors to its rooms
    (and rooms joined to corridors are not roads), so it stays one region for the room stage.

    With ``free``, ``occupied``, ``known`` and ``rays`` (cell masks), roads are floor between blocks: a component
    at least half of whose free cells are ``rays`` (thin free space the map's cleaning kept) and whose free space
    is bounded (4-neighbours not free) by unknown cells more often than by ``occupied`` ones is no road network.
    Laser rays fanning into a room the robot never entered are thin free space between unknown cells, which the
    lines through that unknown cut into a grid of corridor-like and junction-like faces.

    Returns
    -------
    (C,) bool
        Indexed by component id; False for 0.
    """
    n_comp = int(component.max()) + 1
    area = np.bincount(component, weights=face_free_px, minlength=n_comp)
    road = np.isin(face_label, [PlaceLabel.CORRIDOR.value, PlaceLabel.JUNCTION.value])
    road_area = np.bincount(component, weights=face_free_px * road, minlength=n_comp)
    is_junction = (face_label == PlaceLabel.JUNCTION.value) & (face_free_px > 0)
    junctions = np.bincount(component, weights=is_junction, minlength=n_comp)
    door_faces = sub.edge_faces[cogency.door].ravel()
    has_door = np.bincount(component[door_faces], minlength=n_comp) > 0
    out: npt.NDArray[np.bool_] = (road_area >= min_road_share * np.maximum(area, 1)) & (junctions > 0) & ~has_door
    out[0] = False
    if free is not None and occupied is not None and known is not None and rays is not None and out.any():
        out &= ~_fans_of_rays(sub.face_image, component, out, free, occupied, known, rays)
    return out


def _fans_of_rays(
    face_image: npt.NDArray[np.int32],
    component: npt.NDArray[np.int64],
    candidate: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    known: npt.NDArray[np.bool_],
    rays: npt.NDArray[np.bool_],
) -> npt.NDArray[np.bool_]:
    """Per component id (only ``candidate`` ones; the others False): at least half of the free cells of its faces
    are ``rays``, and the cells bounding them (4-neighbours not free, each counted once per free neighbour) are
    more often unknown than ``occupied``."""
    n = int(component.max()) + 1
    if not rays.any():  # (a map the cleaning left no rays on: a rack hall)
        return np.zeros(n, dtype=bool)
    comp = lookup(np.where(candidate[component], component, 0), face_image)  # the candidates' cells (lines: none)
    comp[~free] = 0
    rows, cols = np.flatnonzero(comp.any(axis=1)), np.flatnonzero(comp.any(axis=0))
    box = (slice(max(0, rows[0] - 1), rows[-1] + 2), slice(max(0, cols[0] - 1), cols[-1] + 2))
    comp, free, occupied, known, rays = comp[box], free[box], occupied[box], known[box], rays[box]
    size = np.bincount(comp.ravel(), minlength=n)
    thin = np.bincount(comp[rays], minlength=n)
    h, w = comp.shape
    hit = np.zeros(n, dtype=np.int64)
    unseen = np.zeros(n, dtype=np.int64)
    for a, b in (((slice(0, h - 1), slice(None)), (slice(1, h), slice(None))),
                 ((slice(None), slice(0, w - 1)), (slice(None), slice(1, w)))):
        for inside, beyond in ((a, b), (b, a)):
            mine = comp[inside]
            at = (mine > 0) & ~free[beyond]
            hit += np.bincount(mine[at & occupied[beyond]], minlength=n)
            unseen += np.bincount(mine[at & ~known[beyond]], minlength=n)
    out: npt.NDArray[np.bool_] = candidate & (2 * thin >= size) & (unseen > hit)
    return out


def face_regions(
    sub: Subdivision,
    cogency: EdgeCogency,
    component: npt.NDArray[np.int64],
    face_label: npt.NDArray[np.int64],
    split: npt.NDArray[np.bool_],
) -> npt.NDArray[np.int64]:
    """Region id per face (0 = none).

    A connected component (faces joined by connected links) is one region, unless ``split`` (per
    component id: a warehouse floor, :func:`warehouse_floors`, or a road network,
    :func:`road_networks`): then it is split into pallet cells (each storage face alone),
    junctions (adjacent junction faces together) and aisles or roads (adjacent faces of one
    drivable label together).
    """
    n = sub.n_faces + 1
    apart = split[component]
    a, b = sub.edge_faces[:, 0], sub.edge_faces[:, 1]
    same = (component[a] == component[b]) & ~cogency.cogent & (component[a] > 0)
    join = same & (~apart[a] | ((face_label[a] == face_label[b]) & (face_label[a] != PlaceLabel.STORAGE.value)))
    return link_components(n, sub.edge_faces[join], component > 0)


class RegionInfo(NamedTuple):
    """One region of the map.

    ``label`` and ``category`` are the area-weighted majority of its faces; area in square
    metres; centroid in map metres.
    """

    region_id: int
    label: PlaceLabel
    category: int
    area_m2: float
    centroid_xy_m: tuple[float, float]


def region_topology(
    sub: Subdivision,
    cogency: EdgeCogency,
    face_region: npt.NDArray[np.int64],
    regions: dict[int, RegionInfo],
    *,
    segments: npt.NDArray[np.int32] | None = None,
    doorways: npt.NDArray[np.bool_] | None = None,
    min_border_px: int = 1,
    closure: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]] | None = None,
) -> nx.Graph:
    """Graph of regions; an edge per touching pair with attribute ``connection`` (a Connection value).

    Regions touching across at least one non-cogent edge are linked by their labels
    (:func:`link_connection`); touching only across cogent edges, by a door when a doorway was
    closed on one of them, else they are disconnected. With ``segments`` and ``doorways`` (the
    closed doorway pixels, also those found off the lines), regions whose pixels touch along at
    least ``min_border_px`` border pixel pairs are linked by a door when at least half of their
    shared border is on a doorway, else by their labels (two road pieces touching at the corner of
    a crossing are no passage). ``closure`` is :func:`border_closure` of ``segments`` and ``doorways``, when known.
    """
    import networkx as nx  # imported when first needed (decompose loads it early)

    graph = nx.Graph()
    for info in regions.values():
        graph.add_node(
            info.region_id,
            label=info.label.name.lower(),
            category=info.category,
            area_m2=round(info.area_m2, 3),
            x=round(info.centroid_xy_m[0], 3),
            y=round(info.centroid_xy_m[1], 3),
        )
    ra, rb = face_region[sub.edge_faces[:, 0]], face_region[sub.edge_faces[:, 1]]
    ok = (ra > 0) & (rb > 0) & (ra != rb)
    pairs: dict[tuple[int, int], list[int]] = {}
    at = np.flatnonzero(ok)
    for e, lo, hi in zip(at.tolist(), np.minimum(ra, rb)[at].tolist(), np.maximum(ra, rb)[at].tolist(), strict=True):
        pairs.setdefault((lo, hi), []).append(e)
    cogent, door_edge = cogency.cogent, cogency.door  # (a property: computed once, not per pair)
    for (p, q), edges in pairs.items():
        if p not in regions or q not in regions:
            continue
        open_edges = [e for e in edges if not cogent[e]]
        door = bool(door_edge[edges].any())
        conn = link_connection(regions[p].label, regions[q].label, cogent=not open_edges, door=door)
        graph.add_edge(p, q, connection=conn.value)
    if segments is not None and doorways is not None:
        touching, total, shut = border_closure(segments, doorways) if closure is None else closure
        for (p, q), t, c in zip(touching.tolist(), total.tolist(), shut.tolist(), strict=True):
            if p in regions and q in regions and t >= min_border_px:
                door = 2 * c >= t
                conn = link_connection(regions[p].label, regions[q].label, cogent=door, door=door)
                graph.add_edge(p, q, connection=conn.value)
    return graph
