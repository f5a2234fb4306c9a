"""Cleaning a real SLAM map before it is decomposed: wall fringes, specks and laser streaks.

A map a robot made is not a floor plan. Its walls carry a fringe of half-seen cells (grey in the
image, "free" by map_server's thresholds), single cells flicker between free and occupied, and a
lidar looking through glass, open doors and gaps leaves thin streaks of free space far outside the
building, or a fan of them into a room it never entered. The decomposition sees every free pixel
as floor: a streak becomes a region, a fringe pixel a piece of room on the wall, a speck a piece of
furniture that cuts a room. :func:`clean_occupancy` returns the map the decomposition should see.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import components_stats_runs, lookup, near

FREE_PERCENT = 25
OCCUPIED_PERCENT = 65


class Cleaning(NamedTuple):
    """What :func:`clean_occupancy` changed, as (H, W) bool masks of the input."""

    fringe: npt.NDArray[np.bool_]  # half-seen free cells at walls, now occupied
    specks: npt.NDArray[np.bool_]  # isolated obstacle specks in free space, now free
    streaks: npt.NDArray[np.bool_]  # thin free space (laser streaks), now unknown
    filled: npt.NDArray[np.bool_]  # unknown gaps inside dense fans of free space, now free
    rays: npt.NDArray[np.bool_]  # thin free space that stays (rays near rooms, fans): its edges are no walls


def _disk(radius_px: int) -> npt.NDArray[np.uint8]:
    size = 2 * radius_px + 1
    return np.asarray(cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)), dtype=np.uint8)


def _small_components(mask: npt.NDArray[np.bool_], max_area_px: int) -> npt.NDArray[np.bool_]:
    """Pixels of 8-connected components of ``mask`` of at most ``max_area_px`` pixels."""
    n, parts, stats, runs = components_stats_runs(mask, 8)
    small = stats[:, cv2.CC_STAT_AREA] <= max_area_px
    small[0] = False
    out: npt.NDArray[np.bool_] = lookup(small, parts, runs) if n > 1 else np.zeros(mask.shape, dtype=bool)
    return out


def _specks(free: npt.NDArray[np.bool_], occupied: npt.NDArray[np.bool_], max_area_px: int) -> npt.NDArray[np.bool_]:
    """Occupied components of at most ``max_area_px`` pixels with only free cells around them.

    A small blob on a wall or at unknown space is no speck. At one pixel (0.05 m maps) a speck is an
    occupied cell whose 8 neighbours on the map are all free: a 3 x 3 count of the cells not free, no labelling.
    """
    if max_area_px == 1:
        not_free = cv2.boxFilter((~free).view(np.uint8), -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
        speck: npt.NDArray[np.bool_] = occupied & (not_free == 1)
        return speck
    candidate = _small_components(occupied, max_area_px)
    other = cv2.dilate((~free & ~candidate).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    n, parts = cv2.connectedComponents(candidate.astype(np.uint8), connectivity=8)
    touched = np.zeros(n, dtype=bool)
    touched[np.unique(parts[other & candidate])] = True
    touched[0] = True
    untouched: npt.NDArray[np.bool_] = ~np.take(touched, np.asarray(parts))
    return untouched


def _fringe(
    free: npt.NDArray[np.bool_], uncertain: npt.NDArray[np.bool_], depth_px: int
) -> npt.NDArray[np.bool_]:
    """Uncertain free cells joined to an obstacle through uncertain cells, within ``depth_px`` of it."""
    if not uncertain.any():
        return np.zeros(free.shape, dtype=bool)
    candidate = uncertain & near(~free, depth_px)
    # a candidate component counts when it touches a non-free cell
    n, parts = cv2.connectedComponents(candidate.astype(np.uint8), connectivity=8)
    touching = np.zeros(n, dtype=bool)
    grown = cv2.dilate((~free).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    touching[np.unique(parts[grown & candidate])] = True
    touching[0] = False
    fringe: npt.NDArray[np.bool_] = np.take(touching, np.asarray(parts))
    return fringe


def clean_occupancy(
    occupancy: npt.NDArray[np.integer],
    *,
    resolution_m: float,
    clear_free_percent: int = 1,
    fringe_depth_m: float = 0.3,
    speck_max_area_m2: float = 0.0025,
    streak_width_m: float = 0.25,
    fan_gap_m: float = 0.25,
    min_free_area_m2: float = 0.5,
    streak_reach_m: float = 0.5,
    fill_fans: bool = False,
) -> tuple[npt.NDArray[np.int16], Cleaning]:
    """The map the decomposition should see: fringes to wall, specks and streaks removed.

    Steps, each on the result of the one before:

    1. *Wall fringe*: free cells that are not clearly free (occupancy more than
       ``clear_free_percent`` above the map's clearest free cell: an image's grey between the free
       threshold and white, a live log-odds map's cells seen free fewer times than its clamp) and lie
       within ``fringe_depth_m`` of an obstacle, joined to it through such cells, are occupied. Maps
       read with integer percentages keep them; trinary maps (0/100/-1) have none. Measuring from the
       clearest free cell matters for live maps, whose free cells never read 0: from 0, every free
       cell of the demo warehouse's map within 0.3 m of an upright became wall and its racks were lost.
    2. *Specks*: occupied components of at most ``speck_max_area_m2`` (one cell at 5 cm: rack
       uprights are small obstacles too) with only free cells around them are free.
    3. *Fans and streaks*: free space narrower than ``streak_width_m`` (morphological opening)
       or in components under ``min_free_area_m2`` becomes unknown where it lies more than
       ``streak_reach_m`` from the rest: the sparse rays through glass and gaps outside the
       building; gaps between furniture legs stay. A room seen through its door as a dense fan of
       rays stays: the unknown wedges between rays (thin, off walls, between rays closer than
       ``2 * fan_gap_m``) are bridged first, and with ``fill_fans`` they become free.

    Parameters
    ----------
    occupancy : (H, W) integer
        -1 unknown, 0..100 percent (any row order).
    resolution_m : float
        Metres per cell.

    Returns
    -------
    (H, W) int16
        Cleaned occupancy, same convention.
    Cleaning
        The masks of what changed.
    """
    occ = np.asarray(occupancy).astype(np.int16, copy=False)  # only read
    known = occ >= 0
    free = known & (occ < FREE_PERCENT)
    occupied = known & (occ > OCCUPIED_PERCENT)
    px = resolution_m**2

    # 0 in an image; a live map's clamp (12 % by default)
    clearest = int(np.min(occ, where=free, initial=np.iinfo(np.int16).max)) if free.any() else 0
    fringe = _fringe(free, free & (occ > clearest + clear_free_percent),
                     max(1, round(fringe_depth_m / resolution_m)))
    free &= ~fringe
    occupied |= fringe

    specks = _specks(free, occupied, int(speck_max_area_m2 / px + 1e-9))
    free |= specks
    occupied &= ~specks

    unknown = ~free & ~occupied
    gap = max(1, round(fan_gap_m / resolution_m))
    width = max(1, round(streak_width_m / resolution_m / 2))
    # rays: free space too thin for the opening; a fan of them closes into a body (the masks go to OpenCV and come
    # back as 0/1 bytes viewed as bool: no copies)
    rays = free & ~cv2.morphologyEx(free.view(np.uint8), cv2.MORPH_OPEN, _disk(width)).view(bool)
    closed = cv2.morphologyEx(free.view(np.uint8), cv2.MORPH_CLOSE, _disk(gap)).view(bool)
    between_rays = cv2.morphologyEx(rays.view(np.uint8), cv2.MORPH_CLOSE, _disk(gap)).view(bool)
    # never next to a wall: the unknown cells along a wall (its grey edge) are wall
    off_walls = ~near(occupied, gap)
    # only thin unknown (no disk of the gap's radius fits): the wedges between rays, not the
    # bays of a ragged border with a large unknown space behind it
    thin = ~cv2.morphologyEx(unknown.view(np.uint8), cv2.MORPH_OPEN, _disk(gap)).view(bool)
    filled = closed & unknown & off_walls & thin & between_rays
    body = free | filled
    opened = cv2.morphologyEx(body.view(np.uint8), cv2.MORPH_OPEN, _disk(width)).view(bool)
    kept = opened & ~_small_components(opened, max(1, round(min_free_area_m2 / px)))
    # thin free space near the body (gaps between furniture legs, corners) stays
    reach = ~near(kept, streak_reach_m / resolution_m)
    streaks = free & ~kept & reach
    filled &= kept & fill_fans
    free = (free & ~streaks) | filled

    # whole-image passes, no boolean gathers: free and occupied are disjoint here
    out = np.where(known, occ, np.int16(-1))
    np.maximum(out, np.int16(100), out=out, where=occupied)
    np.copyto(out, np.int16(0), where=free & ~(known & (occ < FREE_PERCENT)))
    np.copyto(out, np.int16(-1), where=streaks)
    return out, Cleaning(fringe=fringe, specks=specks, streaks=streaks, filled=filled, rays=rays & free)
