"""Seeded synthetic warehouse occupancy grids with ground-truth place labels (test helper).

Rack rows are uprights (0.1 m squares) at about 2.7 m pitch along the row, rows 1.1 m deep,
placed back to back with a 0.2 m flue; aisles 2.8-3.5 m; cross aisles 3.2-4 m cut every row
into sections; a perimeter aisle runs inside the outer walls; 10 % of the uprights are missing.
An optional second building holds a rotated block of racks. Ground truth codes follow
``Label``: corridor (aisles and cross aisles), junction (aisle x cross-aisle crossings), storage
(rack footprints), 0 off free space.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition import Label

UPRIGHT_M = 0.1
DEPTH_M = 1.1
FLUE_M = 0.2


class Warehouse(NamedTuple):
    """A synthetic map: occupancy in GridLayer order, ground-truth labels, junction centres (px)."""

    occupancy: npt.NDArray[np.int8]
    truth: npt.NDArray[np.uint8]
    junctions_px: list[tuple[float, float]]
    resolution_m: float


def _block(
    rng: np.random.Generator,
    *,
    n_double_rows: int,
    n_sections: int,
    bays_per_section: int,
    resolution_m: float,
    missing: float,
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.uint8], list[tuple[float, float]]]:
    """One walled block of racks, axis aligned; returns occupancy (row 0 = low y), truth, junctions."""
    pitch = rng.uniform(2.6, 2.8)
    aisles = rng.uniform(2.8, 3.5, n_double_rows + 1)
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
    truth = np.full((h, w), Label.CORRIDOR.value, dtype=np.uint8)
    px = round(wall / resolution_m)
    occ[:px, :] = occ[-px:, :] = occ[:, :px] = occ[:, -px:] = 100
    half = UPRIGHT_M / 2

    def fill(arr: npt.NDArray[np.generic], x0: float, x1: float, y0: float, y1: float, value: int) -> None:
        arr[
            round(y0 / resolution_m) : round(y1 / resolution_m), round(x0 / resolution_m) : round(x1 / resolution_m)
        ] = value

    for y0 in rows_y:
        lines = [y0, y0 + DEPTH_M, y0 + DEPTH_M + FLUE_M, y0 + 2 * DEPTH_M + FLUE_M]
        for xs in xs_sections:
            xe = xs + bays_per_section * pitch
            fill(truth, xs, xe, y0, y0 + 2 * DEPTH_M + FLUE_M, Label.STORAGE.value)
            for k in range(bays_per_section + 1):
                ux = xs + k * pitch
                for uy in lines:
                    if rng.random() >= missing:
                        fill(occ, ux - half, ux + half, uy - half, uy + half, 100)
    junctions: list[tuple[float, float]] = []
    cross_x = [wall] + [xs + bays_per_section * pitch for xs in xs_sections]
    aisle_y = [wall] + [y0 + 2 * DEPTH_M + FLUE_M for y0 in rows_y]
    for i, cx in enumerate(cross_x):
        for j, ay in enumerate(aisle_y):
            corner = i in (0, len(cross_x) - 1) and j in (0, len(aisle_y) - 1)
            if corner:  # an L bend of the perimeter aisle, not a junction
                continue
            fill(truth, cx, cx + cross[i], ay, ay + aisles[j], Label.JUNCTION.value)
            junctions.append(((cx + cross[i] / 2) / resolution_m, (ay + aisles[j] / 2) / resolution_m))
    truth[occ > 0] = 0
    truth[:px, :] = truth[-px:, :] = truth[:, :px] = truth[:, -px:] = 0
    return occ, truth, junctions


def synthetic_warehouse(
    seed: int,
    *,
    resolution_m: float = 0.05,
    n_double_rows: int = 4,
    n_sections: int = 2,
    bays_per_section: int = 8,
    rotated_block_rad: float | None = None,
    missing: float = 0.1,
) -> Warehouse:
    """A warehouse map; with ``rotated_block_rad`` a second, rotated building stands beside the first."""
    rng = np.random.default_rng(seed)
    occ, truth, junctions = _block(
        rng,
        n_double_rows=n_double_rows,
        n_sections=n_sections,
        bays_per_section=bays_per_section,
        resolution_m=resolution_m,
        missing=missing,
    )
    margin = round(1.0 / resolution_m)
    if rotated_block_rad is None:
        big = np.full((occ.shape[0] + 2 * margin, occ.shape[1] + 2 * margin), -1, dtype=np.int8)
        gt = np.zeros(big.shape, dtype=np.uint8)
        big[margin:-margin, margin:-margin] = occ
        gt[margin:-margin, margin:-margin] = truth
        shifted = [(x + margin, y + margin) for x, y in junctions]
        return Warehouse(big, gt, shifted, resolution_m)
    occ2, truth2, junctions2 = _block(
        rng, n_double_rows=3, n_sections=2, bays_per_section=5, resolution_m=resolution_m, missing=missing
    )
    h2, w2 = occ2.shape
    diag = math.ceil(math.hypot(h2, w2)) + 2
    centre = (diag / 2, diag / 2)
    rot = cv2.getRotationMatrix2D((w2 / 2, h2 / 2), math.degrees(rotated_block_rad), 1.0)
    rot[:, 2] += (centre[0] - w2 / 2, centre[1] - h2 / 2)
    known2 = cv2.warpAffine(np.ones((h2, w2), np.uint8), rot, (diag, diag), flags=cv2.INTER_NEAREST) > 0
    occ2r = cv2.warpAffine(occ2.astype(np.uint8), rot, (diag, diag), flags=cv2.INTER_NEAREST).astype(np.int8)
    occ2r[~known2] = -1
    truth2r = cv2.warpAffine(truth2, rot, (diag, diag), flags=cv2.INTER_NEAREST)
    truth2r[occ2r != 0] = 0
    h1, w1 = occ.shape
    height = max(h1, diag) + 2 * margin
    width = w1 + diag + 3 * margin
    big = np.full((height, width), -1, dtype=np.int8)
    gt = np.zeros((height, width), dtype=np.uint8)
    big[margin : margin + h1, margin : margin + w1] = occ
    gt[margin : margin + h1, margin : margin + w1] = truth
    x2 = w1 + 2 * margin
    view = big[margin : margin + diag, x2 : x2 + diag]
    view[known2] = occ2r[known2]
    gt[margin : margin + diag, x2 : x2 + diag][known2] = truth2r[known2]
    out_j = [(x + margin, y + margin) for x, y in junctions]
    for jx, jy in junctions2:
        p = rot @ np.array([jx, jy, 1.0])
        out_j.append((float(p[0]) + x2, float(p[1]) + margin))
    return Warehouse(big, gt, out_j, resolution_m)
