"""Cleaning a real SLAM map before decomposing it."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from services.grid_decomposition import decompose
from services.grid_decomposition.cleaning import clean_occupancy

RES = 0.05


def _room() -> npt.NDArray[np.int8]:
    """A 6 m x 4 m walled room in unknown space (0.1 m walls), GridLayer order."""
    occ = np.full((120, 160), -1, dtype=np.int8)
    occ[20:100, 20:140] = 100
    occ[22:98, 22:138] = 0
    return occ


def test_a_speck_in_the_room_becomes_free() -> None:
    occ = _room()
    occ[60, 80] = 100
    cleaned, what = clean_occupancy(occ, resolution_m=RES)
    assert cleaned[60, 80] == 0 and what.specks[60, 80]


def test_a_blob_on_the_wall_is_no_speck() -> None:
    occ = _room()
    occ[22, 80] = 100  # on the wall's inner face
    cleaned, _ = clean_occupancy(occ, resolution_m=RES)
    assert cleaned[22, 80] == 100


def test_a_laser_streak_outside_the_building_is_removed() -> None:
    occ = _room()
    occ[60, 138:140] = 0  # a gap in the wall (glass) ...
    occ[60, 140:159] = 0  # ... and the ray beyond it, 1 px wide in unknown space
    cleaned, what = clean_occupancy(occ, resolution_m=RES)
    assert np.all(cleaned[60, 150:159] == -1) and what.streaks[60, 150:159].all()
    assert np.all(cleaned[30:90, 30:130] == 0)  # the room's floor stays


def test_a_live_map_keeps_its_floor_along_walls_and_uprights() -> None:
    """A log-odds map's free cells never read 0 (they stop at the clamp, 12 % by default): floor
    seen as often as the rest is no fringe, however near an obstacle, and an upright keeps its aisle."""
    occ = _room()
    occ[22:98, 22:138] = 12
    occ[60:62, 60:62] = 100  # an upright 2 x 2 cells
    occ[22:98, 22:24] = 20  # seen free fewer times along the left wall: fringe, as in an image
    cleaned, what = clean_occupancy(occ, resolution_m=RES)
    assert np.all(cleaned[22:98, 24:30] == 12) and not what.fringe[22:98, 24:30].any()
    assert np.all(cleaned[57:65, 57:60] == 12) and np.all(cleaned[60:62, 60:62] == 100)
    assert np.all(cleaned[22:98, 22:24] == 100) and what.fringe[22:98, 22:24].all()


@pytest.mark.parametrize("resolution_m", [RES, RES / 2])  # a speck is 1 cell at 5 cm, up to 4 cells at 2.5 cm
def test_specks_at_the_map_edge_and_beside_walls(resolution_m: float) -> None:
    """A speck at the map's edge with only free cells beside it is free; one touching a wall, even at a corner, or
    touching another obstacle cell is no speck."""
    occ = np.zeros((40, 40), dtype=np.int8)
    occ[10:30, 20] = 100  # a wall
    occ[0, 0] = occ[39, 17] = 100  # alone at the map's corner and edge
    occ[9, 21] = 100  # diagonal to the wall's end
    occ[35:37, 30] = 100  # a 2-cell blob: a speck at 2.5 cm only
    occ[20, 5] = 100  # alone in the middle
    cleaned, what = clean_occupancy(occ, resolution_m=resolution_m)
    assert cleaned[0, 0] == cleaned[39, 17] == cleaned[20, 5] == 0 and what.specks[20, 5]
    assert cleaned[9, 21] == 100 and np.all(cleaned[10:30, 20] == 100)
    assert np.all(cleaned[35:37, 30] == (0 if resolution_m < RES else 100))


def test_an_isolated_free_speck_in_unknown_space_is_removed() -> None:
    occ = _room()
    occ[5:8, 5:8] = 0
    cleaned, _ = clean_occupancy(occ, resolution_m=RES)
    assert np.all(cleaned[5:8, 5:8] == -1)


def test_grey_fringe_at_a_wall_becomes_wall_and_clear_floor_stays() -> None:
    occ = _room()
    occ[22:98, 22:24] = 12  # half-seen cells along the left wall
    occ[50:52, 80:82] = 12  # the same grey alone in the middle of the room
    cleaned, what = clean_occupancy(occ, resolution_m=RES)
    assert np.all(cleaned[22:98, 22:24] == 100) and what.fringe[22:98, 22:24].all()
    assert np.all(cleaned[50:52, 80:82] == 12)


def test_trinary_map_of_clean_rooms_is_unchanged() -> None:
    occ = _room()
    cleaned, _ = clean_occupancy(occ, resolution_m=RES)
    assert np.array_equal(cleaned, occ)


def test_decomposition_labels_no_fringe_and_a_streak_only_near_its_room() -> None:
    occ = np.full((120, 300), -1, dtype=np.int8)
    occ[:, :160] = _room()
    occ[22:98, 22:24] = 12
    occ[60, 138:140] = 0  # a gap in the wall and a 1 px ray 8 m out through it
    occ[60, 140:299] = 0
    result = decompose(occ, resolution_m=RES)
    room = result.segments[60, 80]
    assert room > 0
    assert not result.segments[22:98, 22:24].any()
    assert result.segments[60, 145] == room  # the ray by the room is the room's free space
    assert not result.segments[60, 220:299].any()  # far out it is no region


def _fan(occ: npt.NDArray[np.int8], origin: tuple[int, int], angles_deg: list[int], length_px: int) -> None:
    """Free rays 2 px wide from ``origin`` (row, col) over the unknown cells of ``occ``."""
    rays = np.zeros(occ.shape, np.uint8)
    for a in np.radians(angles_deg):
        end = (round(origin[1] + length_px * np.cos(a)), round(origin[0] + length_px * np.sin(a)))
        cv2.line(rays, (origin[1], origin[0]), end, 1, 2)
    occ[(rays > 0) & (occ == -1)] = 0


def test_rays_seen_through_an_outer_wall_are_no_region_and_rays_into_a_closed_room_are() -> None:
    """ROSE\u00b2 ``map_with_clutter``: bundles of rays just outside the outer wall (seen through glass) were
    regions of their own, each a segment in no room. Rays into a small walled room nobody entered stay one."""
    occ = np.full((160, 220), -1, dtype=np.int8)
    occ[20:100, 20:200] = 100
    occ[22:98, 22:198] = 0  # a 8.8 m x 3.8 m room
    _fan(occ, (101, 60), [20, 40, 60, 80, 100, 120, 140, 160], 50)  # beyond its wall: outside
    occ[98:150, 130:200] = 100  # a 3.3 m x 2.4 m room above it, walled, seen only as rays
    occ[100:148, 132:198] = -1
    _fan(occ, (100, 165), [30, 50, 70, 90, 110, 130, 150], 60)
    segments = decompose(occ, resolution_m=RES).segments
    room = segments[60, 100]
    assert room > 0
    assert not segments[100:160, 20:128].any()  # the rays outside: no region (one of 1146 px before)
    closed = segments[100:148, 132:198]
    assert np.count_nonzero(closed) > 500 and room not in np.unique(closed)


def _two_furnished_rooms() -> npt.NDArray[np.int8]:
    """Two 5 m x 4 m rooms side by side, a 0.9 m door between them, desks, specks and a ray outside."""
    occ = np.full((120, 260), -1, dtype=np.int8)
    occ[20:102, 20:226] = 100
    occ[22:100, 22:122] = 0
    occ[22:100, 124:224] = 0
    occ[55:73, 122:124] = 0  # the door
    rng = np.random.default_rng(3)
    for r0, c0 in ((30, 35), (70, 80), (35, 140), (75, 190)):  # 1.5 m x 0.8 m desks
        occ[r0 : r0 + 16, c0 : c0 + 30] = 100
    for r, c in rng.integers((25, 25), (97, 220), size=(30, 2)):  # lone flickering cells
        if occ[r, c] == 0:
            occ[r, c] = 100
    occ[90, 224:226] = 0  # glass: a gap in the outer wall ...
    occ[90, 226:259] = 0  # ... and a ray beyond it
    return occ


def test_two_rooms_joined_by_a_door_stay_two_regions_on_a_cluttered_map() -> None:
    occ = _two_furnished_rooms()
    segments = decompose(occ, resolution_m=RES).segments
    left, right = segments[22:100, 22:122], segments[22:100, 124:224]
    assert (left > 0).mean() > 0.8 and (right > 0).mean() > 0.8
    # no region holds a tenth of both rooms
    for region in np.unique(segments[segments > 0]):
        assert min((left == region).mean(), (right == region).mean()) < 0.1, region


def test_wall_fringes_of_the_ipa_maps_lie_outside_every_ground_truth_room() -> None:
    from pathlib import Path

    from PIL import Image

    from services.grid_decomposition.mapfile import read_map_file

    folder = Path(__file__).resolve().parents[4] / "shared" / "data" / "maps" / "ipa_room_segmentation"
    if not folder.exists():
        pytest.skip(f"{folder} is absent: the ipa maps are not on this machine")
    for name in ("Freiburg52_scan", "lab_intel", "office_b"):
        occ, _, _ = read_map_file(folder / f"{name}.png", resolution_m=RES)
        _, what = clean_occupancy(occ, resolution_m=RES)
        with Image.open(folder / f"{name}_gt_segmentation.png") as image:
            rooms = np.asarray(image.convert("L"))[::-1] > 250
        assert what.fringe.any(), name
        assert not (what.fringe & rooms).any(), name
