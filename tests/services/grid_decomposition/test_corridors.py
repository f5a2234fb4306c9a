"""Corridors first: a room open onto a corridor where the map never drew its wall parts from the corridor."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.grid_decomposition.corridors import (
    _by_offset,
    _coordinates,
    _corner_range,
    _row_runs,
    _runs,
    _walls_along,
    band_box,
    corridor_bands,
    part_rooms_from_corridors,
    tilted_lines,
)
from services.grid_decomposition.radiogram import Line

RESOLUTION_M = 0.05


def _corridor_and_room(seen_wall_m: float) -> tuple[np.ndarray, list[Line]]:
    """Walls of a 33 m x 2.5 m corridor (rows 100..149) and a 6 m x 5 m room above it (rows 152..250,
    columns 300..420) open onto the corridor over its whole width (6 m, wider than the corridor: no neck).
    The corridor's upper wall is drawn for ``seen_wall_m`` on each side of the opening; the lines are the
    walls' (as the decomposition's line search finds them)."""
    walls = np.zeros((260, 700), dtype=bool)
    walls[98:100, 18:682] = True  # the corridor's lower wall
    walls[100:150, [18, 19, 680, 681]] = True  # its ends
    reach = round(seen_wall_m / RESOLUTION_M)
    walls[150:152, 300 - reach : 300] = walls[150:152, 421 : 421 + reach] = True  # its upper wall, but the opening
    walls[150:253, [298, 299, 421, 422]] = True  # the room's side walls
    walls[251:253, 298:423] = True  # and its far wall
    horizontal = [Line(0.0, float(y), 30.0, 0.1, True) for y in (99, 150, 251)]
    vertical = [Line(math.pi / 2, -float(x), 5.0, 0.1, True) for x in (299, 421)]
    return walls, horizontal + vertical


def _one_region(walls: np.ndarray) -> np.ndarray:
    segments = np.zeros(walls.shape, dtype=np.int32)
    segments[100:150, 20:680] = 1
    segments[150:251, 300:421] = 1
    segments[walls] = 0
    return segments


def test_a_room_open_onto_a_corridor_where_its_wall_is_missing_is_a_region_of_its_own() -> None:
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    segments = _one_region(walls)
    out = part_rooms_from_corridors(segments, walls, lines, np.array([False, True]), resolution_m=RESOLUTION_M)
    room = np.unique(out[160:245, 305:415])
    corridor = np.unique(out[101:149, 21:679])
    assert room.size == 1 and corridor.size == 1, "the room and the whole corridor are one region each"
    assert room[0] != corridor[0] and room[0] > 0 and corridor[0] > 0
    assert np.array_equal(out > 0, segments > 0), "every pixel of the region stays in a region"


def test_the_corridor_is_found_as_a_band_between_its_walls() -> None:
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    segments = _one_region(walls)
    bands = corridor_bands(segments == 1, walls, lines, top=0, left=0, resolution_m=RESOLUTION_M)
    assert [(b.offset_a_px, b.offset_b_px) for b in bands] == [(99, 150)]
    assert bands[0].t0_px <= 25 and bands[0].t1_px >= 675, "the band runs the corridor's whole length"


def test_a_wall_not_yet_seen_along_the_corridor_parts_nothing() -> None:
    # a growing map: the corridor's upper wall has been seen for only 1 m on each side of the opening (the robot
    # has not been further): no corridor band is known yet and the region stays whole
    walls, lines = _corridor_and_room(seen_wall_m=1.0)
    segments = _one_region(walls)
    out = part_rooms_from_corridors(segments, walls, lines, np.array([False, True]), resolution_m=RESOLUTION_M)
    assert np.array_equal(out, segments)


def test_an_open_hall_is_no_corridor_and_stays_whole() -> None:
    # a 20 m x 12 m hall with lines across it (its walls' and a column row's) but no wall along any pair of
    # lines 1-3 m apart
    walls = np.zeros((260, 420), dtype=bool)
    walls[[8, 9, 250, 251], 8:412] = True
    walls[8:252, [8, 9, 410, 411]] = True
    walls[128:132, 100:104] = walls[128:132, 300:304] = True  # two columns
    lines = [Line(0.0, float(y), 20.0, 0.1, True) for y in (9, 130, 160, 250)]
    lines += [Line(math.pi / 2, -float(x), 12.0, 0.1, True) for x in (9, 102, 140, 302, 410)]
    segments = np.zeros(walls.shape, dtype=np.int32)
    segments[10:250, 10:410] = 1
    segments[walls] = 0
    out = part_rooms_from_corridors(segments, walls, lines, np.array([False, True]), resolution_m=RESOLUTION_M)
    assert np.array_equal(out, segments)


def test_regions_not_offered_are_left_alone() -> None:
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    segments = _one_region(walls)
    out = part_rooms_from_corridors(segments, walls, lines, np.array([False, False]), resolution_m=RESOLUTION_M)
    assert np.array_equal(out, segments)


def test_pieces_of_the_corridor_cut_apart_before_join_it_and_a_room_beside_it_does_not() -> None:
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    segments = _one_region(walls)
    segments[100:150, 20:200] = np.where(segments[100:150, 20:200] > 0, 2, 0)  # the corridor's left end, cut off
    segments[100:150, 200] = 0  # by a cut
    segments[160:200, 20:100] = 3  # a room beside it, not along it
    joinable = np.array([False, True, True, True])
    out = part_rooms_from_corridors(
        segments, walls, lines, np.array([False, True, False, False]), resolution_m=RESOLUTION_M, joinable=joinable
    )
    corridor = out[101:149, 21:679]
    assert np.unique(corridor[corridor > 0]).size == 1, "the corridor is one region again (but the cut's pixels)"
    assert np.unique(out[160:200, 20:100]).tolist() == [3]
    room = np.unique(out[160:245, 305:415])
    assert room.size == 1 and room[0] not in (0, 3, out[120, 100])


def _bands_pair_by_pair(
    region: np.ndarray, occupied: np.ndarray, lines: list[Line], *, min_w: int = 20, max_w: int = 60, tol: int = 2
) -> list[tuple[float, int, int, int, int]]:
    """The band search one pair of lines at a time, with full-resolution counts (what the search did before
    it took every pair at once): (angle, offsets, run) of every walled clear run, best walled first."""
    found = []
    for angle in sorted({round(ln.angle_rad, 4) for ln in lines}):
        u, t = _coordinates(region.shape, 0, 0, angle)
        u0, t0 = int(u.min()), int(t.min())
        nu, nt = int(u.max()) - u0 + 1, int(t.max()) - t0 + 1
        key = (u - u0) * nt + (t - t0)
        every = np.cumsum(np.bincount(key.ravel(), minlength=nu * nt).reshape(nu, nt), axis=0)
        inside = np.cumsum(np.bincount(key[region], minlength=nu * nt).reshape(nu, nt), axis=0)
        walls = np.zeros((nu + 2 * tol, nt), dtype=bool)
        for d in range(2 * tol + 1):  # an occupied cell within the tolerance across
            np.logical_or.at(walls, (u[occupied] - u0 + d, t[occupied] - t0), True)
        walls = walls[tol:-tol]
        every, inside = np.vstack([np.zeros((1, nt), int), every]), np.vstack([np.zeros((1, nt), int), inside])
        offsets = sorted({round(ln.offset_px) - u0 for ln in lines if round(ln.angle_rad, 4) == angle} & set(range(nu)))
        for i, a in enumerate(offsets):
            for b in (b for b in offsets[i + 1 :] if min_w <= b - a <= max_w):
                lo, hi = a + tol + 1, b - tol
                total = every[hi] - every[lo]
                clear = (total > 0) & (inside[hi] - inside[lo] >= 0.9 * np.maximum(total, 1))
                for s, e in zip(*_runs(clear), strict=True):
                    side_a, side_b = walls[a, s:e].mean(), walls[b, s:e].mean()
                    long = e - s >= max(120, round(3.0 * (b - a)))
                    if long and min(side_a, side_b) >= 0.3 and (side_a + side_b) / 2 >= 0.35:
                        found.append(((side_a + side_b) / 2, (angle, a + u0, b + u0, int(s) + t0, int(e) - 1 + t0)))
    return [band for _, band in sorted(found, key=lambda f: -f[0])]


@pytest.mark.parametrize("turn", [0.0, 0.3])
def test_the_band_search_takes_the_bands_a_pair_by_pair_search_takes(turn: float) -> None:
    """Corridors of several widths, some walls broken, the whole map turned: the bands found taking every pair
    of lines at once are those a search pair by pair finds, in its order (no pair is narrower than another
    band's strip here, so none is left out)."""
    walls, lines = _corridor_and_room(12.0)
    walls[20:22, 18:682] = True  # two more corridors, 2 m and 1.9 m wide, their wall between them broken
    walls[60:62, 18:500] = True
    walls[60:62, 100:140] = walls[60:62, 300:330] = False
    lines += [Line(0.0, 21.0, 30.0, 0.1, True), Line(0.0, 61.0, 30.0, 0.1, True)]
    if turn:
        size = (walls.shape[1], walls.shape[0])
        m = cv2.getRotationMatrix2D((0.0, 0.0), -math.degrees(turn), 1.0)
        m[:, 2] = (0.0, 200.0)
        walls = cv2.warpAffine(walls.astype(np.uint8), m, (size[0] + 200, size[1] + 500), flags=cv2.INTER_NEAREST) > 0
        lines = [
            Line(ln.angle_rad + turn, ln.offset_px + (200.0 * math.cos(ln.angle_rad + turn)), 30.0, 0.1, True)
            for ln in lines
        ]
    region = ~walls
    region[:, :5] = False
    reference = _bands_pair_by_pair(region, walls, lines)
    assert reference  # the test looks at bands
    bands = corridor_bands(region, walls, lines, top=0, left=0, resolution_m=RESOLUTION_M, min_length_m=6.0)
    taken = [(b.angle_rad, b.offset_a_px, b.offset_b_px, b.t0_px, b.t1_px) for b in bands]
    assert taken == [band for band in reference if band in taken]
    assert set(taken) <= set(reference)


def test_row_runs_are_the_runs_of_every_row() -> None:
    flags = np.random.default_rng(3).random((7, 40)) < 0.6
    flags[2] = False
    flags[4] = True
    row, starts, ends = _row_runs(flags)
    for r in range(flags.shape[0]):
        s, e = _runs(flags[r])
        assert np.array_equal(starts[row == r], s) and np.array_equal(ends[row == r], e)


def test_walls_along_a_few_lines_are_the_dilated_raster_at_them() -> None:
    rng = np.random.default_rng(5)
    across = np.repeat(np.arange(60, dtype=np.intp)[:, None], 50, axis=1)
    along = np.repeat(np.arange(50, dtype=np.int32)[None, :], 60, axis=0)
    occupied = rng.random((60, 50)) < 0.05
    rows = np.array([0, 3, 5, 30, 58, 59])
    raster = cv2.dilate(occupied.astype(np.uint8), np.ones((5, 1), np.uint8)).astype(bool)
    # along places from 7 (a window's own coordinates), the occupied pixels by their flat indices
    at = np.flatnonzero(occupied)
    walls = _walls_along(np.take(across, at), np.take(along, at) + 7, rows, 60, 7, 50, 2)
    assert np.array_equal(walls, raster[rows])


@pytest.mark.parametrize("angle", [-0.0001, 1.5707, 2.5, -1.2])
@pytest.mark.parametrize("left", [-300, -40, 0, 25])
def test_a_table_by_offset_reads_as_the_table_by_offset_from_the_least(angle: float, left: int) -> None:
    """A window's across offsets, negative, from 0 and positive: the same entries as with the least subtracted."""
    u, _ = _coordinates((40, 70), 5, left, angle)
    u0, u1 = _corner_range(u)
    table = np.random.default_rng(left + 400).integers(-1000, 1000, u1 - u0 + 1)
    box = (slice(3, 31), slice(2, 70))
    assert np.array_equal(np.take(_by_offset(table, u0), u[box]), np.take(table, u[box] - u0))


@pytest.mark.parametrize("angle", [-0.0001, 0.0, 0.3, 0.7854, 1.5707, 2.5, -1.2, -0.035])
@pytest.mark.parametrize("shape", [(1, 1), (1, 40), (30, 1), (90, 130)])
def test_a_windows_coordinates_range_is_at_its_corners(angle: float, shape: tuple[int, int]) -> None:
    for coordinate in _coordinates(shape, 17, -40, angle):
        assert _corner_range(coordinate) == (int(coordinate.min()), int(coordinate.max()))


@pytest.mark.parametrize("angle", [-0.0001, 0.3, 1.5707, 2.5, -1.2])
def test_a_bands_box_holds_all_its_pixels(angle: float) -> None:
    u, t = _coordinates((90, 130), 17, 40, angle)
    rng = np.random.default_rng(round(abs(angle) * 1000))
    for _ in range(20):
        a, b = sorted(rng.integers(int(u.min()) - 5, int(u.max()) + 5, 2).tolist())
        t0, t1 = sorted(rng.integers(int(t.min()) - 5, int(t.max()) + 5, 2).tolist())
        everywhere = (u >= a) & (u <= b) & (t >= t0) & (t <= t1)
        box = band_box(u, t, (a, b), (t0, t1))
        assert np.count_nonzero(everywhere[box]) == np.count_nonzero(everywhere)


def _turned(image: np.ndarray, degrees: float) -> np.ndarray:
    """``image`` (uint8) turned by ``degrees`` about its centre (nearest pixel), in a frame 60 px larger each way."""
    big = np.zeros((image.shape[0] + 120, image.shape[1] + 120), dtype=np.uint8)
    big[60:-60, 60:-60] = image
    turn = cv2.getRotationMatrix2D((big.shape[1] / 2, big.shape[0] / 2), degrees, 1.0)
    return np.asarray(cv2.warpAffine(big, turn, (big.shape[1], big.shape[0]), flags=cv2.INTER_NEAREST))


def test_a_corridor_in_a_wing_drawn_askew_parts_from_its_room_along_its_own_walls() -> None:
    # the corridor and room of the first test turned by 2 degrees (a wing of a building the map drew askew) while
    # the building's lines stay at 0 and 90 degrees: over its 33 m the corridor drifts 1.2 m off them
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    truth = np.zeros(walls.shape, dtype=np.uint8)
    truth[105:145, 25:675] = 1  # well inside the corridor
    truth[160:245, 305:415] = 2  # and the room
    segments = _turned(_one_region(walls).astype(np.uint8), 2.0).astype(np.int32)
    walls, truth = _turned(walls.astype(np.uint8), 2.0) > 0, _turned(truth, 2.0)
    segments[walls] = 0
    assert not corridor_bands(segments == 1, walls, lines, top=0, left=0, resolution_m=RESOLUTION_M)
    out = part_rooms_from_corridors(segments, walls, lines, np.array([False, True]), resolution_m=RESOLUTION_M)
    room, corridor = np.unique(out[truth == 2]), np.unique(out[truth == 1])
    assert room.size == 1 and corridor.size == 1, "the room and the whole corridor are one region each"
    assert room[0] != corridor[0] and room[0] > 0 and corridor[0] > 0


def test_walls_along_the_lines_give_no_tilted_line() -> None:
    # the walls of the first test, square to the lines: a wall lies on tilted lines too, but runs at the angle
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    assert tilted_lines(walls, lines, top=0, left=0, resolution_m=RESOLUTION_M) == []
    tilted = tilted_lines(_turned(walls.astype(np.uint8), 2.0) > 0, lines, top=0, left=0, resolution_m=RESOLUTION_M)
    assert tilted, "the turned walls give lines"
    off = [abs(math.degrees(ln.angle_rad) - round(math.degrees(ln.angle_rad) / 90) * 90) for ln in tilted]
    assert all(abs(o - 2.0) <= 0.5 for o in off), "at the walls' own angle (within a step), 2 degrees off the lines'"
