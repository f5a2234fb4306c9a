"""Doorway closing along lines, cell decomposition and edge cogency."""

from __future__ import annotations

import math

import numpy as np

from services.grid_decomposition import Line, LineGroup, close_doorways, edge_cogency, subdivide, wall_evidence


def test_close_doorways_bridges_a_door_between_walls_but_not_furniture_legs() -> None:
    profile = np.zeros(60, dtype=bool)
    profile[0:20] = True  # wall
    profile[38:60] = True  # wall after an 18-cell door
    profile[25] = True  # a chair leg in the doorway
    wall, g0, g1 = close_doorways(profile, min_wall_px=5, max_door_px=20)
    assert wall[:20].all() and wall[38:].all() and not wall[20:38].any()
    assert (g0.tolist(), g1.tolist()) == ([20], [38])
    _, g0, _ = close_doorways(profile, min_wall_px=5, max_door_px=10)
    assert g0.size == 0


def test_close_doorways_bridges_two_doors_split_by_a_post_but_not_an_open_side() -> None:
    profile = np.zeros(100, dtype=bool)
    profile[0:20] = True  # wall
    profile[56:100] = True  # wall after a 36-cell opening
    posts = profile.copy()
    posts[37:39] = True  # a post: two doors of 17 and 18 cells
    _, g0, g1 = close_doorways(profile, min_wall_px=5, max_door_px=20)
    assert g0.size == 0
    _, g0, g1 = close_doorways(profile, min_wall_px=5, max_door_px=20, posts=posts)
    assert (g0.tolist(), g1.tolist()) == ([20], [56])
    posts[37:39] = False
    posts[24] = True  # a speck near one end leaves 31 cells open: no doorway
    _, g0, _ = close_doorways(profile, min_wall_px=5, max_door_px=20, posts=posts)
    assert g0.size == 0


def test_a_line_across_a_room_through_its_furniture_is_no_row_of_doors() -> None:
    # a line from a wall along it to a wall crossing it (its run only as long as the wall is thick), 36 cells between
    # them split by a piece of furniture into two door-wide stretches: doors in a wall, unless that wall only crosses
    profile = np.zeros(100, dtype=bool)
    profile[0:20] = True  # a wall along the line
    profile[56:64] = True  # a wall crossing it: 8 cells thick
    posts = np.zeros(100, dtype=bool)
    posts[37:39] = True
    _, g0, g1 = close_doorways(profile, min_wall_px=5, max_door_px=20, posts=posts)
    assert (g0.tolist(), g1.tolist()) == ([20], [56])
    _, g0, _ = close_doorways(profile, min_wall_px=5, max_door_px=20, posts=posts, post_wall_px=10)
    assert g0.size == 0
    profile[56:70] = True  # the wall goes on along the line: two doors again
    _, g0, g1 = close_doorways(profile, min_wall_px=5, max_door_px=20, posts=posts, post_wall_px=10)
    assert (g0.tolist(), g1.tolist()) == ([20], [56])
    profile[34:37] = True  # a pier between two ordinary doorways (no posts needed): not concerned
    _, g0, _ = close_doorways(profile, min_wall_px=2, max_door_px=20, post_wall_px=30)
    assert g0.tolist() == [20, 37]


def test_a_post_the_line_only_grazes_splits_no_gap_into_doors() -> None:
    # two walls along the line, 36 cells apart: a post in the middle of the gap makes two door-wide stretches when
    # the line passes through it; a post whose tolerance disc the line only touches (one sample) leaves one opening
    profile = np.zeros(100, dtype=bool)
    profile[0:20] = profile[56:80] = True
    through, grazed = np.zeros(100, dtype=bool), np.zeros(100, dtype=bool)
    through[36:40] = True
    grazed[38] = True
    for posts, doors in ((through, [20]), (grazed, [])):
        _, g0, _ = close_doorways(profile, min_wall_px=5, max_door_px=20, posts=posts, post_min_px=2)
        assert g0.tolist() == doors
    _, g0, _ = close_doorways(profile, min_wall_px=5, max_door_px=20, posts=grazed)  # as before: any sample counts
    assert g0.tolist() == [20]


def test_close_doorways_of_several_lines_at_once_closes_each_line_alone() -> None:
    """Profiles one after the other: a wall ending one line and a wall starting the next are two runs with no
    doorway between them, a short run split by the change of line is no wall, and each line's own doors and posts
    close as they do alone."""
    rng = np.random.default_rng(3)
    profiles = [rng.random(int(rng.integers(1, 80))) < 0.7 for _ in range(12)]
    profiles[3][-4:] = profiles[4][:4] = True  # 4 + 4 cells across a change of line: two short runs
    posts = [p | (rng.random(p.size) < 0.2) for p in profiles]
    first = np.cumsum([0] + [p.size for p in profiles[:-1]])
    wall, g0, g1 = close_doorways(
        np.concatenate(profiles), min_wall_px=5, max_door_px=6, posts=np.concatenate(posts), first=first
    )
    alone = [close_doorways(p, min_wall_px=5, max_door_px=6, posts=q) for p, q in zip(profiles, posts, strict=True)]
    assert np.array_equal(wall, np.concatenate([w for w, _, _ in alone]))
    assert np.array_equal(g0, np.concatenate([a + f for (_, a, _), f in zip(alone, first, strict=True)]))
    assert np.array_equal(g1, np.concatenate([b + f for (_, _, b), f in zip(alone, first, strict=True)]))


def test_subdivide_two_crossing_lines_gives_four_faces_and_four_edges() -> None:
    lines = (Line(0.0, 50.0, 1.0, 0.1, True), Line(math.pi / 2, -40.0, 1.0, 0.1, True))
    sub = subdivide([LineGroup(lines, None)], (100, 80))
    assert sub.n_faces == 4
    assert sub.n_edges == 4
    assert len(sub.vertices_px) == 1
    assert np.allclose(sub.vertices_px[0], (40.0, 50.0))
    degree = np.bincount(sub.edge_faces.ravel(), minlength=5)[1:]
    assert (degree == 2).all()


def test_wall_with_a_door_is_cogent_and_an_open_line_is_not() -> None:
    occ = np.zeros((100, 100), dtype=bool)
    occ[:, 50] = True
    occ[40:58, 50] = False  # 18 px door
    free = ~occ
    lines = (Line(math.pi / 2, -50.0, 5.0, 0.1, True), Line(0.0, 20.0, 5.0, 0.1, True))
    groups = [LineGroup(lines, None)]
    sub = subdivide(groups, occ.shape, domain=free)
    wall, door = wall_evidence(
        occ, groups, tolerance_px=1, min_wall_px=5, max_door_px=25, widening_px=6, max_depth_px=20
    )
    cog = edge_cogency(sub, occ.astype(np.int16) * 100, free, wall, door)
    assert sub.n_edges >= 3
    crosses_wall = np.array(
        [
            abs(sub.edge_ends_px[e, 0, 0] - 50) < 2 and abs(sub.edge_ends_px[e, 1, 0] - 50) < 2
            for e in range(sub.n_edges)
        ]
    )
    assert cog.cogent[crosses_wall].all()
    assert cog.door[crosses_wall].any()
    assert not cog.cogent[~crosses_wall].any()


def test_the_doorways_of_several_lines_are_each_lines_own() -> None:
    occ = np.zeros((100, 100), dtype=bool)
    occ[5:95, 30] = occ[5:95, 70] = True
    occ[20:30, 30] = False  # a 10 px door in one wall
    occ[50:72, 70] = False  # a 22 px door in the other: the gaps of both lines are judged together
    lines = [Line(math.pi / 2, -30.0, 5.0, 0.1, True), Line(math.pi / 2, -70.0, 5.0, 0.1, True)]

    def evidence(on: list[Line]) -> tuple[np.ndarray, np.ndarray]:
        return wall_evidence(
            occ, [LineGroup(tuple(on), None)], tolerance_px=1, min_wall_px=5, max_door_px=25, widening_px=6,
            max_depth_px=20,
        )

    wall, door = evidence(lines)
    alone = [evidence([ln]) for ln in lines]
    assert door[20:30, 30].all() and door[50:72, 70].all()
    assert np.array_equal(wall, alone[0][0] | alone[1][0])
    assert np.array_equal(door, alone[0][1] | alone[1][1])


def test_a_speck_beside_a_line_is_no_post_between_two_doors_one_on_it_is() -> None:
    # a wall along x = 50 with a 1.8 m gap (36 px at 5 cm); a speck of furniture 1 px off the line is a post between
    # two 0.85 m doors (the gap is closed); 2 px off, the line only touches the rim of its 0.1 m tolerance disc
    occ = np.zeros((100, 100), dtype=bool)
    occ[5:95, 49:52] = True
    occ[32:68, 49:52] = False
    line = [LineGroup((Line(math.pi / 2, -50.0, 5.0, 0.1, True),), None)]

    def closed(speck_col: int) -> bool:
        posts = np.zeros(occ.shape, dtype=bool)
        posts[50, speck_col] = True
        _, door = wall_evidence(
            occ, line, tolerance_px=2, min_wall_px=5, max_door_px=20, widening_px=6, max_depth_px=20, posts=posts,
            post_min_px=2,
        )
        return bool(door[40, 50] and door[60, 50])

    assert closed(51)
    assert not closed(52)


def test_face_occupancy_is_the_mean_of_its_pixels_as_summed_in_raster_order() -> None:
    rng = np.random.default_rng(5)
    percent = rng.integers(0, 25, (90, 120)).astype(np.int16)  # free cells of every occupancy below 25 %
    percent[rng.random(percent.shape) < 0.5] = 0
    percent[:, 60] = 100
    percent[:3, 60] = -1  # unknown: occupied
    occ = np.where(percent < 0, 1.0, percent / 100.0)
    free = occ < 0.25
    lines = (Line(0.0, 30.0, 1.0, 0.1, True), Line(math.pi / 2, -90.0, 1.0, 0.1, True))
    sub = subdivide([LineGroup(lines, None)], occ.shape, domain=free)
    none = np.zeros(occ.shape, dtype=bool)
    cog = edge_cogency(sub, percent, free, none, none)
    faces = sub.face_image.ravel()
    area = np.bincount(faces, minlength=sub.n_faces + 1)
    mean = np.bincount(faces, weights=occ.ravel(), minlength=sub.n_faces + 1)[1:] / area[1:]
    assert np.array_equal(cog.face_occupancy[1:], mean)  # the same bits
    assert np.array_equal(cog.face_free_px[1:], area[1:])
    assert cog.face_occupancy[0] == 1.0 and cog.face_free_px[0] == 0


def test_a_line_through_a_door_and_across_the_corridor_beyond_is_no_row_of_doors() -> None:
    # 5 cm pixels. A room (rows 10-67) above a 1.5 m corridor (rows 71-100), a 1.1 m door in the wall between them
    # (x 40-62) with a speck in it; a pier hangs from the room's top wall down to row 30 and a block lies below the
    # corridor. The vertical line x = 50 from the pier's foot to the block is a 3.5 m gap split by the speck into a
    # stretch of the room's floor and one across the corridor: no two doors side by side.
    occ = np.zeros((150, 200), dtype=bool)
    occ[:10] = occ[101:] = True
    occ[68:71] = True
    occ[68:71, 40:63] = False
    occ[10:31, 48:53] = True
    posts = np.zeros(occ.shape, dtype=bool)
    posts[64:68, 50] = True
    line = [LineGroup((Line(math.pi / 2, -50.0, 5.0, 0.1, True),), None)]

    def closed(grid: np.ndarray, corridor_length_px: int) -> bool:
        _, door = wall_evidence(
            grid, line, tolerance_px=2, min_wall_px=10, max_door_px=40, widening_px=6, max_depth_px=20, posts=posts,
            post_wall_px=15, post_min_px=2, corridor_length_px=corridor_length_px,
        )
        return bool(door[40:60, 50].any() or door[75:98, 50].any())

    assert closed(occ, 0)  # the posts rule alone: two "doors"
    assert not closed(occ, 40)
    # the same line between two rooms, the wall between them with a 3.5 m opening split by a post: two doors
    rooms = np.zeros(occ.shape, dtype=bool)
    rooms[:10] = rooms[140:] = True
    rooms[:, 48:53] = True
    rooms[31:101, 48:53] = False
    assert closed(rooms, 40)


def test_a_block_the_line_runs_along_is_no_post_between_two_doors_a_post_on_it_is() -> None:
    # 5 cm pixels. A 1.5 m corridor (rows 20-49) under a wall block (rows 0-19: the line x = 50 continues a side wall
    # of the rooms above it) opens onto a hall below (rows 50-149, the corridor's lower wall only east of x 100); a
    # pillar of wall stands in the hall at rows 82-120. The line from the wall down to the pillar is a 3.1 m gap. A
    # block of furniture beside the line (rows 50-75, x 51-70: the line runs along its face) leaves between it and
    # the wall a stretch the floor does not widen behind on the block's side (the corridor, between wall and block)
    # and between it and the pillar a sliver no one passes: no doors side by side, the corridor and the hall stay
    # one. A post on the line (a speck) splits it into two stretches that each open onto the hall on both sides:
    # doors side by side, as before.
    occ = np.zeros((150, 200), dtype=bool)
    occ[:20] = True
    occ[50:53, 100:] = True
    occ[53:, 100:] = True
    occ[82:121, 45:56] = True
    line = [LineGroup((Line(math.pi / 2, -50.0, 5.0, 0.1, True),), None)]

    crossed = np.zeros(occ.shape, dtype=bool)

    def closed(posts: np.ndarray) -> bool:
        crossed[:] = False
        _, door = wall_evidence(
            occ, line, tolerance_px=2, min_wall_px=10, max_door_px=40, widening_px=6, max_depth_px=20, posts=posts,
            post_wall_px=15, post_min_px=2, corridor_length_px=40, side_by_side_out=crossed,
        )
        return bool(door[22:45, 50].any())

    block = np.zeros(occ.shape, dtype=bool)
    block[50:76, 51:71] = True
    speck = np.zeros(occ.shape, dtype=bool)
    speck[55:59, 50:52] = True
    assert not closed(block)
    # the gap left open is marked as a line across open floor (from the wall down to the pillar), nothing else
    assert crossed[22:80, 50].all() and not crossed[:, :45].any() and not crossed[:, 56:].any()
    assert closed(speck)
    assert not crossed.any()
