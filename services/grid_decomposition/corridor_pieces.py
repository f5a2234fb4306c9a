"""A corridor the room stage cut in pieces is one region again, and the rooms that leak into it part from it."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.corridors import _coordinates, band_mask, corridor_bands
from services.grid_decomposition.radiogram import Line


def _room_like(piece: npt.NDArray[np.bool_], *, min_area_px: float, min_radius_px: float, min_solidity: float) -> bool:
    """At least ``min_area_px``, a disc of ``min_radius_px`` fits, area at least ``min_solidity`` of its hull."""
    area = int(np.count_nonzero(piece))
    if area < min_area_px:
        return False
    if cv2.distanceTransform(np.pad(piece, 1).astype(np.uint8), cv2.DIST_L2, 5).max() < min_radius_px:
        return False
    outline, _ = cv2.findContours(piece.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return area >= min_solidity * cv2.contourArea(cv2.convexHull(np.concatenate(outline)))


def join_corridor_pieces(
    segments: npt.NDArray[np.int32],
    lines: list[Line],
    joinable: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    min_piece_share: float = 0.5,
    min_pieces_share: float = 0.5,
    room_min_area_m2: float = 8.0,
    room_min_radius_m: float = 1.0,
    room_min_solidity: float = 0.6,
    margin_px: int = 4,
) -> npt.NDArray[np.int32]:
    """Make every corridor band that the room stage cut in pieces one region; part the rooms leaking into it.

    The bands (:func:`~services.grid_decomposition.corridors.corridor_bands`) are looked for in the union
    of the ``joinable`` regions (per region id: a room region, no warehouse floor), with every pixel in no
    region as wall: a corridor's walls are often drawn as a grey band with few occupied cells. A band is a
    corridor cut in pieces when the regions lying at least ``min_piece_share`` inside its strip hold at
    least ``min_pieces_share`` of the strip: a band through the middle of a room (an aisle beside desks)
    is a small part of the room's region and is left alone. The strip of such a band becomes one region;
    what each region it crossed keeps outside the strip splits into 4-connected pieces, of which the
    room-like ones (at least ``room_min_area_m2``, a ``room_min_radius_m`` disc fits, area at least
    ``room_min_solidity`` of the convex hull) stay regions (the largest keeps the region's id) and the
    others (a door's niche, a sliver along the wall) join the corridor when they touch it.

    Returns
    -------
    (H, W) int32
        The segments; the corridor takes the id of the region that held most of its strip, parted
        rooms beyond the first of a region are numbered after the existing ids.
    """
    region = (segments > 0) & joinable[segments]
    if not region.any():
        return segments
    rows, cols = np.flatnonzero(region.any(axis=1)), np.flatnonzero(region.any(axis=0))
    top, left = max(0, int(rows[0]) - margin_px), max(0, int(cols[0]) - margin_px)
    box = slice(top, int(rows[-1]) + 1 + margin_px), slice(left, int(cols[-1]) + 1 + margin_px)
    window = segments[box]
    inside = region[box]
    bands = corridor_bands(inside, window == 0, lines, top=top, left=left, resolution_m=resolution_m)
    if not bands:
        return segments
    shape = (window.shape[0], window.shape[1])
    coordinates = {a: _coordinates(shape, top, left, a) for a in {band.angle_rad for band in bands}}
    out = window.copy()
    next_id = int(segments.max()) + 1
    taken = np.zeros(shape, dtype=bool)
    limits = {
        "min_area_px": room_min_area_m2 / resolution_m**2,
        "min_radius_px": room_min_radius_m / resolution_m,
        "min_solidity": room_min_solidity,
    }
    for band in bands:
        strip = band_mask(band, *coordinates[band.angle_rad]) & inside & ~taken
        n = int(out.max()) + 1
        size = np.bincount(out.ravel(), minlength=n)
        held = np.bincount(out[strip], minlength=n)
        held[0] = 0
        pieces = held >= min_piece_share * np.maximum(size, 1)
        if held[pieces].sum() < min_pieces_share * np.count_nonzero(strip):
            continue
        corridor_id = int(np.argmax(held))
        crossed = np.flatnonzero(held)
        corridor = strip.copy()
        for k in crossed.tolist():
            n_parts, parts, stats, _ = cv2.connectedComponentsWithStats(
                ((out == k) & ~strip).astype(np.uint8), connectivity=4
            )
            areas = stats[:, cv2.CC_STAT_AREA].copy()
            areas[0] = 0
            no_room = np.ones(n_parts, dtype=bool)
            no_room[0] = False
            keeps = k != corridor_id  # the largest room-like piece keeps the region's id
            for p in np.argsort(-areas)[: np.count_nonzero(areas >= limits["min_area_px"])].tolist():
                x, y, w, h = stats[p, :4]
                part = parts[y : y + h, x : x + w] == p
                if not _room_like(part, **limits):
                    continue
                no_room[p] = False
                if keeps:
                    keeps = False
                else:
                    out[y : y + h, x : x + w][part] = next_id
                    next_id += 1
            corridor |= no_room[parts]
        # the pieces that are no room join the corridor only where they touch it
        n_parts, parts = cv2.connectedComponents(corridor.astype(np.uint8), connectivity=4)
        touching = np.unique(parts[strip])
        corridor = np.isin(parts, touching[touching > 0])
        out[corridor] = corridor_id
        taken |= corridor
    result = segments.copy()
    result[box] = out
    return result
