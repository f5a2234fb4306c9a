"""Furniture told from walls: which free-standing obstacle pieces of an occupancy map stand on a room's floor.

One rule for the grid decomposition (``services/grid_decomposition/rooms.py``: furniture joins its room's
segment) and the floor plan (``services/floor_plan/rooms.py``: furniture takes the label of its room), with one
set of numbers, :class:`FurnitureRule`; each stage labels the pieces its own way and adds its own steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class FurnitureRule:
    """What a free-standing obstacle piece is to be furniture (:func:`furniture_pieces`); lengths in metres."""

    max_m2: float = 1.0
    """A small piece: at most this large and ``max_extent_m`` long (chairs, bins, table legs, pillars) ..."""
    max_extent_m: float = 1.2
    wall_min_length_m: float = 0.5
    """... unless it is a piece of wall: at least this long and at most ``wall_max_thickness_m`` thick."""
    wall_max_thickness_m: float = 0.35
    block_max_m2: float = 1.7
    """A block: at most this large and ``block_max_extent_m`` long, solid (``block_min_solid`` of it survives an
    opening by a disc ``block_min_thickness_m`` wide), at most ``block_max_elongation`` times as long as thick."""
    block_max_extent_m: float = 3.0
    block_min_thickness_m: float = 0.4
    block_max_elongation: float = 3.0
    block_min_solid: float = 0.3


def furniture_pieces(
    obstacle: npt.NDArray[np.bool_] | npt.NDArray[np.uint8],
    parts: npt.NDArray[np.int32],
    stats: npt.NDArray[np.int32],
    *,
    resolution_m: float,
    rule: FurnitureRule,
) -> npt.NDArray[np.bool_]:
    """Which 8-connected pieces of ``obstacle`` are furniture: free-standing furniture, bins, pillars, table legs,
    clutter, desks and cabinets.

    A piece not touching the map border is furniture when

    * it is small: at most ``rule.max_m2`` and at most ``rule.max_extent_m`` on the longer side of its bounding
      box, unless it is a piece of wall: at least ``rule.wall_min_length_m`` long and at most
      ``rule.wall_max_thickness_m`` thick (its minimum-area rectangle), as the dashes of a wall with many doors; or
    * it is a block: at most ``rule.block_max_m2`` and ``rule.block_max_extent_m``, solid (at least
      ``rule.block_min_solid`` of it survives an opening with a disc ``rule.block_min_thickness_m`` wide) and its
      minimum-area rectangle at most ``rule.block_max_elongation`` times as long as wide. A desk or a cabinet
      standing in a real office is seen as such a block (ROSE\u00b2's offices: as walls they closed doorways between
      desks and cut the rooms apart); a free-standing piece of wall, however bent (an L or a T of thin walls, a
      pillar on it), is mostly thin, and a long thick one is elongated. The area limit keeps larger blocks as
      obstacles: the meeting tables with chairs of ipa's furnished offices (about 1.9 m\u00b2) then closed the
      doorways the ipa ground truth has (at 4 m\u00b2, the decomposition's ipa furnished precision fell 0.4 points).

    Longer walls are kept anyway; furniture pushed against a wall is part of the wall's piece and stays.

    Parameters
    ----------
    obstacle : (H, W) bool or uint8
        Occupied or unknown cells (non-zero).
    parts, stats : (H, W) int32, (N + 1, 5) int32
        The pieces of ``obstacle`` as ``cv2.connectedComponentsWithStats(obstacle, connectivity=8)`` labels them.
    resolution_m : float
        Metres per cell.

    Returns
    -------
    (N + 1,) bool
        Per piece id, whether it is furniture (id 0, off ``obstacle``, is not).
    """
    h, w = obstacle.shape
    x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    bw, bh = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]
    inner = (x > 0) & (y > 0) & (x + bw < w) & (y + bh < h)
    area_m2 = stats[:, cv2.CC_STAT_AREA] * resolution_m**2
    extent_m = np.maximum(bw, bh) * resolution_m
    small = inner & (area_m2 <= rule.max_m2) & (extent_m <= rule.max_extent_m)
    block = inner & ~small & (area_m2 <= rule.block_max_m2) & (extent_m <= rule.block_max_extent_m)
    small[0] = block[0] = False
    if block.any():  # solid: most of it survives an opening with a disc as wide as the thickness
        radius = max(1, round(rule.block_min_thickness_m / resolution_m / 2))
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        thick = cv2.morphologyEx(np.asarray(obstacle, np.uint8), cv2.MORPH_OPEN, disc).astype(bool)
        solid = np.bincount(parts[thick], minlength=len(stats)) / np.maximum(stats[:, cv2.CC_STAT_AREA], 1)
        block &= solid >= rule.block_min_solid
    keep = small | block
    for k in np.flatnonzero(keep & (np.hypot(bw, bh) * resolution_m >= rule.wall_min_length_m)).tolist():
        box = parts[y[k] : y[k] + bh[k], x[k] : x[k] + bw[k]] == k
        rows, cols = np.divmod(np.flatnonzero(box), box.shape[1])  # np.nonzero's order, without its multi-index
        _, (side_a, side_b), _ = cv2.minAreaRect(np.stack([cols, rows], axis=1).astype(np.float32))
        length, thickness = (max(side_a, side_b) + 1) * resolution_m, (min(side_a, side_b) + 1) * resolution_m
        if small[k] and length >= rule.wall_min_length_m and thickness <= rule.wall_max_thickness_m:
            keep[k] = False
        if block[k] and length > rule.block_max_elongation * thickness:
            keep[k] = False
    out: npt.NDArray[np.bool_] = keep
    return out
