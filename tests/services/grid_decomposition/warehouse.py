"""Seeded synthetic warehouse occupancy grids with ground-truth place labels (test helper).

Rack rows are uprights (0.1 m squares) at about 2.7 m pitch along the row, rows 1.1 m deep,
placed back to back with a 0.2 m flue; aisles 2.8-3.5 m (or any range); cross aisles 3.2-4 m
cut every row into sections; a perimeter aisle runs inside the outer walls; 10 % of the uprights
are missing. An optional second building holds a rotated block of racks, and the whole map can be
turned. Ground truth codes follow ``PlaceLabel``: corridor (aisles and cross aisles), junction (aisle
x cross-aisle crossings, not the L bends of the perimeter aisle), storage (rack footprints), 0
off free space; and every pallet cell (one bay, one side of the flue) has an id.
Also the ground truth of the tuw grid warehouses (``../shared/data/maps/tuw_warehouse``), and rack halls
drawn the ways other maps draw racks (``styled_warehouse``: solid, uprights, pallet height, ...).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.simulator.rackmaps import RackStyle, rack_hall_map
from shared.vocabulary import PlaceLabel

UPRIGHT_M = 0.1
DEPTH_M = 1.1
FLUE_M = 0.2

Points = list[tuple[float, float]]


class Warehouse(NamedTuple):
    """A synthetic map in GridLayer order (row 0 = lowest y).

    Attributes
    ----------
    occupancy : (H, W) int8
        100 occupied, 0 free, -1 unknown.
    truth : (H, W) uint8
        Ground-truth :class:`PlaceLabel` code, 0 off free space.
    cells : (H, W) int32
        Pallet-cell id (1..N) over each bay's footprint, 0 elsewhere (the flue belongs to no cell).
    junctions_px : list of (x, y)
        Centres of the cross-aisle junctions, pixels (x = column, y = row).
    resolution_m : float
    """

    occupancy: npt.NDArray[np.int8]
    truth: npt.NDArray[np.uint8]
    cells: npt.NDArray[np.int32]
    junctions_px: Points
    resolution_m: float


def _block(
    rng: np.random.Generator,
    *,
    n_double_rows: int,
    n_sections: int,
    bays_per_section: int,
    resolution_m: float,
    missing: float,
    aisle_width_m: tuple[float, float],
    first_cell: int,
) -> Warehouse:
    """One walled block of racks, axis aligned, cell ids from ``first_cell``."""
    pitch = rng.uniform(2.6, 2.8)
    aisles = rng.uniform(*aisle_width_m, n_double_rows + 1)
    cross = rng.uniform(3.2, 4.0, n_sections + 1)
    wall = 0.2
    xs_sections: list[float] = []
    x = wall + cross[0]
    for s in range(n_sections):
        xs_sections.append(x)
        x += bays_per_section * pitch + cross[s + 1]
    width = x + wall
    rows_y: list[float] = []
    y = wall + aisles[0]
    for r in range(n_double_rows):
        rows_y.append(y)
        y += 2 * DEPTH_M + FLUE_M + aisles[r + 1]
    height = y + wall
    h, w = round(height / resolution_m), round(width / resolution_m)
    occ = np.zeros((h, w), dtype=np.int8)
    truth = np.full((h, w), PlaceLabel.CORRIDOR.value, dtype=np.uint8)
    cells = np.zeros((h, w), dtype=np.int32)
    px = round(wall / resolution_m)
    occ[:px, :] = occ[-px:, :] = occ[:, :px] = occ[:, -px:] = 100
    half = UPRIGHT_M / 2

    def fill(arr: npt.NDArray[np.generic], x0: float, x1: float, y0: float, y1: float, value: int) -> None:
        arr[
            round(y0 / resolution_m) : round(y1 / resolution_m), round(x0 / resolution_m) : round(x1 / resolution_m)
        ] = value

    cell = first_cell
    for y0 in rows_y:
        lines = [y0, y0 + DEPTH_M, y0 + DEPTH_M + FLUE_M, y0 + 2 * DEPTH_M + FLUE_M]
        for xs in xs_sections:
            xe = xs + bays_per_section * pitch
            fill(truth, xs, xe, y0, y0 + 2 * DEPTH_M + FLUE_M, PlaceLabel.STORAGE.value)
            for k in range(bays_per_section + 1):
                ux = xs + k * pitch
                for uy in lines:
                    if rng.random() >= missing:
                        fill(occ, ux - half, ux + half, uy - half, uy + half, 100)
                if k < bays_per_section:
                    fill(cells, ux, ux + pitch, lines[0], lines[1], cell)
                    fill(cells, ux, ux + pitch, lines[2], lines[3], cell + 1)
                    cell += 2
    junctions: Points = []
    cross_x = [wall] + [xs + bays_per_section * pitch for xs in xs_sections]
    aisle_y = [wall] + [y0 + 2 * DEPTH_M + FLUE_M for y0 in rows_y]
    for i, cx in enumerate(cross_x):
        for j, ay in enumerate(aisle_y):
            corner = i in (0, len(cross_x) - 1) and j in (0, len(aisle_y) - 1)
            if corner:  # an L bend of the perimeter aisle, not a junction
                continue
            fill(truth, cx, cx + cross[i], ay, ay + aisles[j], PlaceLabel.JUNCTION.value)
            junctions.append(((cx + cross[i] / 2) / resolution_m, (ay + aisles[j] / 2) / resolution_m))
    truth[occ > 0] = 0
    truth[:px, :] = truth[-px:, :] = truth[:, :px] = truth[:, -px:] = 0
    return Warehouse(occ, truth, cells, junctions, resolution_m)


def _rotate(wh: Warehouse, angle_rad: float) -> Warehouse:
    """The map rotated about its centre onto a square canvas of its diagonal (unknown outside)."""
    h, w = wh.occupancy.shape
    diag = math.ceil(math.hypot(h, w)) + 2
    rot = cv2.getRotationMatrix2D((w / 2, h / 2), math.degrees(angle_rad), 1.0)
    rot[:, 2] += (diag / 2 - w / 2, diag / 2 - h / 2)

    def warp(image: npt.NDArray[np.uint8] | npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        return np.asarray(cv2.warpAffine(image, rot, (diag, diag), flags=cv2.INTER_NEAREST), dtype=np.float32)

    known = warp(np.ones((h, w), np.uint8)) > 0
    occ = warp(wh.occupancy.astype(np.float32)).astype(np.int8)
    occ[~known] = -1
    truth = warp(wh.truth).astype(np.uint8)
    truth[occ != 0] = 0
    cells = warp(wh.cells.astype(np.float32)).astype(np.int32)
    cells[occ != 0] = 0
    moved = [(float(p[0]), float(p[1])) for p in (rot @ np.array([x, y, 1.0]) for x, y in wh.junctions_px)]
    return Warehouse(occ, truth, cells, moved, wh.resolution_m)


def _place(parts: list[tuple[Warehouse, int, int]], shape: tuple[int, int]) -> Warehouse:
    """Maps pasted at (row, column) offsets onto an unknown canvas (their unknown cells stay transparent)."""
    occ = np.full(shape, -1, dtype=np.int8)
    truth = np.zeros(shape, dtype=np.uint8)
    cells = np.zeros(shape, dtype=np.int32)
    points: Points = []
    for wh, r, c in parts:
        h, w = wh.occupancy.shape
        known = wh.occupancy >= 0
        occ[r : r + h, c : c + w][known] = wh.occupancy[known]
        truth[r : r + h, c : c + w][known] = wh.truth[known]
        cells[r : r + h, c : c + w][known] = wh.cells[known]
        points += [(x + c, y + r) for x, y in wh.junctions_px]
    return Warehouse(occ, truth, cells, points, parts[0][0].resolution_m)


def synthetic_warehouse(
    seed: int,
    *,
    resolution_m: float = 0.05,
    n_double_rows: int = 4,
    n_sections: int = 2,
    bays_per_section: int = 8,
    rotated_block_rad: float | None = None,
    rotation_rad: float = 0.0,
    aisle_width_m: tuple[float, float] = (2.8, 3.5),
    missing: float = 0.1,
) -> Warehouse:
    """A warehouse map with a 1 m unknown border.

    With ``rotated_block_rad`` a second walled building holding a block of racks rotated by that
    angle stands 1 m beside the first (a map of two regions at different angles).
    ``rotation_rad`` turns the whole map. Aisle widths are drawn from ``aisle_width_m`` (cross
    aisles stay 3.2-4 m).
    """
    rng = np.random.default_rng(seed)
    wh = _block(
        rng,
        n_double_rows=n_double_rows,
        n_sections=n_sections,
        bays_per_section=bays_per_section,
        resolution_m=resolution_m,
        missing=missing,
        aisle_width_m=aisle_width_m,
        first_cell=1,
    )
    margin = round(1.0 / resolution_m)
    h1, w1 = wh.occupancy.shape
    parts = [(wh, margin, margin)]
    shape = (h1 + 2 * margin, w1 + 2 * margin)
    if rotated_block_rad is not None:
        second = _block(
            rng,
            n_double_rows=3,
            n_sections=2,
            bays_per_section=5,
            resolution_m=resolution_m,
            missing=missing,
            aisle_width_m=aisle_width_m,
            first_cell=int(wh.cells.max()) + 1,
        )
        second = _rotate(second, rotated_block_rad)
        diag = second.occupancy.shape[0]
        parts.append((second, margin, w1 + 2 * margin))
        shape = (max(h1, diag) + 2 * margin, w1 + diag + 3 * margin)
    out = _place(parts, shape)
    return _rotate(out, rotation_rad) if rotation_rad else out


def cell_labels(labels: npt.NDArray[np.uint8], wh: Warehouse) -> npt.NDArray[np.int64]:
    """The majority label of each pallet cell's free pixels, (N,) for cells 1..N; -1 for a cell without any."""
    ok = (wh.cells > 0) & (wh.occupancy == 0)
    n = int(wh.cells.max()) + 1
    votes = np.zeros((n, len(PlaceLabel)), dtype=np.int64)
    np.add.at(votes, (wh.cells[ok], labels[ok]), 1)
    out: npt.NDArray[np.int64] = np.where(votes.sum(axis=1) > 0, votes.argmax(axis=1), -1)
    return out[1:]


def _runs(free: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    """Length of the horizontal free run through every pixel."""
    out = np.zeros(free.shape, dtype=np.int64)
    for r in range(free.shape[0]):
        d = np.diff(np.r_[0, free[r].astype(np.int8), 0])
        for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
            out[r, a:b] = b - a
    return out


def tuw_truth(occupancy: npt.NDArray[np.int8]) -> npt.NDArray[np.uint8]:
    """Corridor / junction ground truth of a tuw grid warehouse (roads between solid blocks).

    A free pixel whose free runs along both axes are longer than 1.5 road widths (the most common
    shorter run) is a junction, every other free pixel corridor. A crossing widened into a square
    is one junction; an L bend would count as one too, but every crossing of these maps is a T or
    an X.
    """
    free = occupancy == 0
    h_run, v_run = _runs(free), _runs(free.T).T
    road = int(np.bincount(np.minimum(h_run, v_run)[free]).argmax())
    truth = np.where(free, PlaceLabel.CORRIDOR.value, 0).astype(np.uint8)
    truth[free & (h_run > 1.5 * road) & (v_run > 1.5 * road)] = PlaceLabel.JUNCTION.value
    return truth


def styled_warehouse(seed: int, *, style: RackStyle, rotation_rad: float = 0.0, **options: Any) -> Warehouse:
    """A rack hall drawn as ``style`` (:func:`services.simulator.rackmaps.rack_hall_map`) as a :class:`Warehouse`.

    The simulator's truth codes are those of :class:`PlaceLabel` (corridor, junction, storage, open area).
    """
    hall = rack_hall_map(seed, style=style, rotation_rad=rotation_rad, **options)
    return Warehouse(hall.occupancy, hall.truth, hall.cells, hall.junctions_px, hall.resolution_m)
