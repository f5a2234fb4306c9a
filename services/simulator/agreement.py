"""How well an occupancy grid built from simulated scans matches the world's true surfaces."""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.simulator.errors import SimulatorError
from services.simulator.groundtruth import ground_truth_grids, surface_mask
from services.simulator.world import World
from shared.store.records import GridLayer

OCCUPIED_PERCENT = 65


class SurfaceAgreement(NamedTuple):
    """Surface recall and occupied precision of a map against ground truth.

    ``surface_recall``: fraction of true surface cells (obstacle outlines at lidar height) within
    the tolerance of an occupied map cell; ``surface_recall_observed``: the same over the surface
    cells the map has observed (known) nearby, i.e. what the robot could have seen;
    ``occupied_precision``: fraction of occupied map cells within the tolerance of a true surface.
    """

    surface_recall: float
    surface_recall_observed: float
    occupied_precision: float
    surface_cells: int
    occupied_cells: int


def _resample(layer: GridLayer, shape: tuple[int, int], origin: tuple[float, float], resolution_m: float
              ) -> npt.NDArray[np.int8]:
    """``layer`` looked up at the centres of a grid of ``shape``, -1 where it has no cell."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    x = origin[0] + (cols + 0.5) * resolution_m
    y = origin[1] + (rows + 0.5) * resolution_m
    c = np.floor((x - layer.origin_x_m) / layer.resolution_m).astype(np.int64)
    r = np.floor((y - layer.origin_y_m) / layer.resolution_m).astype(np.int64)
    inside = (r >= 0) & (c >= 0) & (r < layer.data.shape[0]) & (c < layer.data.shape[1])
    out = np.full(shape, -1, np.int8)
    out[inside] = np.asarray(layer.data)[r[inside], c[inside]]
    return out


def surface_agreement(layer: GridLayer, world: World, *, tolerance_m: float = 0.1, height_m: float = 0.2
                      ) -> SurfaceAgreement:
    """Compare an occupancy ``layer`` in the map frame (int8 -1/0..100) with ``world``'s surfaces.

    Both are compared on the layer's resolution, over the world's ground-truth grid; occupied is
    above 65 %. Distances are Euclidean between cell centres.
    """
    if not (math.isfinite(tolerance_m) and tolerance_m > 0):
        raise SimulatorError(f"tolerance_m must be positive, got {tolerance_m}")
    grids = ground_truth_grids(world, resolution_m=layer.resolution_m, height_m=height_m)
    surface = surface_mask(world, grids, height_m=height_m)
    ours = _resample(layer, surface.shape, (grids.origin_x_m, grids.origin_y_m), layer.resolution_m)
    occupied = ours > OCCUPIED_PERCENT
    if not surface.any() or not occupied.any():
        raise SimulatorError("need true surfaces and occupied map cells to compare")
    to_occupied = cv2.distanceTransform((~occupied).astype(np.uint8), cv2.DIST_L2, 5) * layer.resolution_m
    to_surface = cv2.distanceTransform((~surface).astype(np.uint8), cv2.DIST_L2, 5) * layer.resolution_m
    to_known = cv2.distanceTransform((ours < 0).astype(np.uint8), cv2.DIST_L2, 5) * layer.resolution_m
    slack = tolerance_m + 1e-6
    recalled = to_occupied[surface] <= slack
    observed = to_known[surface] <= slack
    return SurfaceAgreement(
        surface_recall=float(recalled.mean()),
        surface_recall_observed=float(recalled[observed].mean()) if observed.any() else 0.0,
        occupied_precision=float((to_surface[occupied] <= slack).mean()),
        surface_cells=int(surface.sum()),
        occupied_cells=int(occupied.sum()),
    )
