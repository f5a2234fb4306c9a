"""Occupancy grid -> parametric floor plan: units, doors, types (the stage's one entry point)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan.chain import Chain, ChainResult, ChainSettings, run_chain
from services.floor_plan.clutter import explain_clutter, explain_exterior
from services.floor_plan.context import ContextPrior, ContextSettings
from services.floor_plan.detectors import Evidence, wall_line_segments, wall_lines, wbu_candidates
from services.floor_plan.errors import FloorPlanError
from services.floor_plan.frame import (
    Frame,
    dominant_angle,
    make_frame,
    points_to_map,
    points_to_work,
    to_map,
    to_work,
)
from services.floor_plan.fronts import open_fronts, split_at_fronts
from services.floor_plan.kernels import KernelSettings, Proposer
from services.floor_plan.likelihood import (
    SEED_SENSOR_MODEL,
    Canvas,
    CellClass,
    beam_traces,
    cell_prediction_rate,
    classify_map,
    enclosed_blocks,
    log_sensor_table,
    render,
    solid_obstacles,
    wall_thickness_cells,
)
from services.floor_plan.rooms import (
    FurnitureSettings,
    Room,
    RoomSettings,
    cut_off_free,
    fill_free,
    furniture,
    furniture_insides,
    furniture_pockets,
    furniture_reach,
    group_rooms,
    join_insides,
    label_furniture,
    wall_fringe,
)
from services.floor_plan.slanted import slanted, split_at_slanted_walls
from services.floor_plan.walls import Segment, Slant, fit_walls
from services.floor_plan.world import Rect, UnitType, World, shared_band


@dataclass(frozen=True)
class FloorPlanSettings:
    """Everything that tunes the floor plan; lengths in metres."""

    wall_m: float | None = None
    """Wall thickness of a unit; None: the map's own (:func:`~services.floor_plan.likelihood.wall_thickness_cells`,
    1 cell for maps drawn with one-pixel walls, 4 for freiburg's 0.2 m walls)."""
    min_inner_m: float = 0.5
    min_door_m: float = 0.5
    min_line_m: float = 0.8
    occupied_percent: int = 65
    free_percent: int = 25
    trace_max_m: float | None = 0.15
    """Free runs narrower than this beside unknown space (a laser beam's trace through a window or door into space the
    map has not seen, :func:`~services.floor_plan.likelihood.beam_traces`) read as unknown in C_M (eq. 3.7: the chain,
    the walls' fit, the clutter obstacles, K); the rooms and the label images still read them free. None: every free
    cell of the occupancy is free in C_M too (docs/floor_plan.md, branch ``fpseed``: the two over four chain seeds)."""
    sensor_model: tuple[tuple[float, ...], ...] = SEED_SENSOR_MODEL
    overlap_psi: float = 0.2
    obstacle_min_m: float = 0.3
    """Occupied blocks at least this thick everywhere are solid obstacles (racks drawn solid, a filled outside):
    the world renders them as walls and keeps units off them; thinner occupied cells are walls to explain."""
    shift_sigma_m: float = 0.15
    max_shift_m: float = 0.5
    chain: ChainSettings = field(default_factory=ChainSettings)
    context: ContextSettings = field(default_factory=ContextSettings)
    warm_start_iteration: int = 4001
    """Where a warm-started chain enters the schedule: the last phase of table 3.2, every kernel on."""
    min_turn_rad: float = math.radians(1.0)
    """A map whose dominant walls are further than this from the grid's axes is explained turned to them."""
    rooms: RoomSettings = field(default_factory=RoomSettings)
    """When units are one room (:mod:`services.floor_plan.rooms`)."""
    furniture: FurnitureSettings | None = field(default_factory=FurnitureSettings)
    """The map's non-free pieces that are furniture standing on a room's floor (:func:`~services.floor_plan.rooms.
    furniture`): ``rooms.png`` gives each the label of the room round it (``FloorPlan.furniture``); None: none."""
    clutter_max_m2: float | None = 4.0
    """The largest blob of non-free cells inside the units drawn as an obstacle (furniture, the unseen space behind
    it: :mod:`services.floor_plan.clutter`); None: no clutter obstacles, C_W is the seed's world alone."""
    clutter_log_cost: float = 10.0
    """The prior's cost of one clutter obstacle in nats (one cell the sensor model explains is worth log 8 = 2.1).
    The same cap and cost hold for the exterior obstacles (occupied blobs against a wall's outside,
    :func:`~services.floor_plan.clutter.explain_exterior`), drawn when clutter obstacles are."""
    wall_shift_m: float | None = 0.2
    """Walls as the map draws them (:mod:`services.floor_plan.walls`): a segment of a unit's wall moves its inner face
    at most this far either way; None: every wall is the seed's band."""
    wall_extra_m: float = 0.15
    """A wall segment is at most this much thicker than the seed's band (and at least 0: an opening)."""
    wall_segment_m: float = 0.25
    """Wall segments start and end on a grid of this length along each wall."""
    wall_log_cost: float = 10.0
    """The prior's cost of one wall segment other than the seed's band (nats)."""
    fringe_m: float | None = 0.1
    """The label images (``units.png``, ``rooms.png``) leave out the wall fringe: free cells that are not clearly free
    (an image's grey edge along a wall, drawn by antialiasing; cells a live map saw free fewer times) within this of a
    cell that is not free, joined to it through such cells (:func:`~services.floor_plan.rooms.wall_fringe`); None:
    every free cell is labelled. C_M and K(W,M) do not change."""
    fringe_wall_m2: float = 1.0
    """... of a wall: a connected piece of cells that are not free at least this large (furniture is no wall)."""
    fringe_inside_m2: float = 1.5
    """... and not the inside of a piece of furniture: free space enclosed by cells that are not free, at most this
    large and at least ``fringe_inside_depth_m`` from them somewhere (a cupboard drawn as an outline filled light
    grey, :func:`~services.floor_plan.rooms.furniture_insides`; the grid decomposition's ``inside_furniture`` joins
    such space, up to 1.5 m², to its room); 0: every fringe cell is left out."""
    fringe_inside_depth_m: float = 0.1
    fringe_inside_reach_m: float = 0.5
    """``rooms.png`` gives such an inside the room label nearest to it through the furniture round it, up to this far:
    the room the cupboard stands in, not a room of its own (``FloorPlan.insides``)."""
    slant_line_m: float | None = 1.0
    """The map's straight wall lines at least this long (:func:`~services.floor_plan.detectors.wall_line_segments`),
    found once for the slanted walls and the rooms' re-cut along them; None: neither (no lines)."""
    slant_gap_m: float = 1.25
    """... with gaps up to this long bridged (dashed walls, doorways; a line is prolonged by half of it where the rooms
    are re-cut: a dashed wall whose last dash stops short of the wall it meets) ..."""
    slant_wall_share: float = 0.5
    """... lying on or beside the free space's outline over at least this share of their length ..."""
    slant_min_angle_rad: float | None = math.radians(5.0)
    """Walls at an angle to the working grid (a second wall direction, :class:`~services.floor_plan.walls.Slant`):
    the wall lines at least this far from both axes may cut a unit, drawn with the fitted walls and at the same
    cost per wall; None: no slanted walls."""


class Unit(NamedTuple):
    id: int
    rect: Rect  # cells of the plan's working frame
    polygon_xy_m: tuple[tuple[float, float], ...]  # closed ring, 5 points, map frame
    unit_type: UnitType
    probability: float
    area_m2: float


class Door(NamedTuple):
    rect: Rect  # cells of the plan's working frame
    segment_xy_m: tuple[tuple[float, float], tuple[float, float]]
    units: tuple[int, int]
    width_m: float


class FloorPlan(NamedTuple):
    """A floor plan and how well it explains the map.

    ``classes_map``/``classes_world`` are C_M and C_W (uint8 :class:`CellClass`, GridLayer row order, map
    cells); ``k`` is K(W,M) (eq. 3.39). ``world`` and the units' and doors' ``rect`` are cells of ``frame``
    (the map itself unless its walls run at an angle); polygons and segments are map metres.
    """

    world: World
    units: list[Unit]
    doors: list[Door]
    adjacency: list[tuple[int, int]]
    rooms: list[Room]
    """Units joined through open boundaries (parts in cells of ``frame``), re-cut along slanted walls."""
    room_cells: npt.NDArray[np.int32]
    """Each room's index in ``rooms`` + 1 on its free cells (cells of ``frame``), 0 elsewhere."""
    obstacles: list[tuple[tuple[tuple[float, float], ...], ...]]
    """The solid blocks as polygons (outer ring, then holes; closed rings in map metres)."""
    standing: list[bool]
    """Per obstacle: True for a block standing in the building (racks, solid furniture: it does not touch the
    map's border), False for a filled outside."""
    classes_map: npt.NDArray[np.uint8]
    classes_world: npt.NDArray[np.uint8]
    k: float
    k_units: float
    """K(W,M) of the seed's world alone: units, doors and solid blocks, without the clutter obstacles."""
    clutter: int
    """Clutter obstacles drawn in ``classes_world`` (:mod:`services.floor_plan.clutter`)."""
    walls: dict[int, tuple[tuple[Segment, ...], ...]]
    """Per unit id, its four walls as drawn in ``classes_world`` (:mod:`services.floor_plan.walls`; cells of
    ``frame``, :class:`~services.floor_plan.world.Side` order); empty when the walls are the seed's bands."""
    wall_segments: int
    """Wall segments drawn other than the seed's band."""
    slants: dict[int, tuple[Slant, ...]]
    """Per unit id, the slanted walls (at an angle to ``frame``) that cut it (:class:`~services.floor_plan.walls.Slant`,
    cells of ``frame``); only units that have any."""
    exterior: int
    """Exterior obstacles drawn in ``classes_world`` (occupied blobs against the walls' outside)."""
    log_posterior: float
    iterations: int
    accepted: int
    seconds: float
    cpu_seconds: float
    resolution_m: float
    origin_xy_m: tuple[float, float]
    frame: Frame
    fringe: npt.NDArray[np.bool_]
    """The wall fringe (map cells, GridLayer order): free cells the label images leave out (``fringe_m``)."""
    traces: npt.NDArray[np.bool_]
    """Laser beams' traces (map cells, GridLayer order): free cells of the map ``classes_map`` reads unknown
    (``trace_max_m``); the rooms and the label images count them free, as the map draws them."""
    furniture: npt.NDArray[np.bool_] | None = None
    """Furniture (map cells, GridLayer order): non-free pieces of the map that ``rooms.png`` labels with the room round
    them (``FloorPlanSettings.furniture``); None: none."""
    insides: npt.NDArray[np.uint8] | None = None
    """The insides of furniture (map cells, GridLayer order; :func:`~services.floor_plan.rooms.furniture_reach`, 2 on
    an inside, 1 on the furniture round it within ``fringe_inside_reach_m``): ``rooms.png`` gives each the room label
    nearest to it through that furniture (``FloorPlanSettings.fringe_inside_m2``); None: none."""
    pockets: npt.NDArray[np.bool_] | None = None
    """Furniture drawn in the map's unknown grey against a wall (map cells, GridLayer order;
    :func:`~services.floor_plan.rooms.furniture_pockets`): ``rooms.png`` labels each pocket with the one room touching
    it, or within ``pocket_reach_cells`` of it; None: none."""
    pocket_reach_cells: int = 1
    """``FurnitureSettings.pocket_reach_m`` in cells."""
    free_piece_min_cells: int | None = None
    """``RoomSettings.free_piece_min_m2`` in cells: ``rooms.png`` gives each piece of free space no room reaches
    through free space and at least this large the one room within ``free_piece_reach_cells``; None: none."""
    free_piece_reach_cells: int = 1
    """``RoomSettings.free_piece_reach_m`` in cells."""

    @property
    def slanted_walls(self) -> int:
        """Slanted walls drawn in ``classes_world``."""
        return sum(len(cuts) for cuts in self.slants.values())


def _cells(metres: float, resolution_m: float) -> int:
    return max(1, round(metres / resolution_m))


def kernel_settings(settings: FloorPlanSettings, resolution_m: float) -> KernelSettings:
    if settings.wall_m is None:
        raise FloorPlanError("kernel settings need a wall thickness: fit the map first (floor_plan)")
    return KernelSettings(
        wall_cells=_cells(settings.wall_m, resolution_m),
        min_inner_cells=_cells(settings.min_inner_m, resolution_m),
        shift_sigma_cells=max(settings.shift_sigma_m / resolution_m, 0.5),
        max_shift_cells=_cells(settings.max_shift_m, resolution_m),
        min_door_cells=_cells(settings.min_door_m, resolution_m),
    )


def _obstacles(classes: npt.NDArray[np.uint8], settings: FloorPlanSettings,
               resolution_m: float) -> npt.NDArray[np.bool_]:
    return solid_obstacles(classes, min_cells=max(_cells(settings.obstacle_min_m, resolution_m), 3))


def floor_plan(
    occupancy: npt.NDArray[np.integer], *, resolution_m: float, origin_xy_m: tuple[float, float] = (0.0, 0.0),
    settings: FloorPlanSettings | None = None, start: World | None = None, angle_rad: float | None = None,
    trajectory_xy_m: npt.NDArray[np.float64] | None = None,
) -> FloorPlan:
    """Fit a world of units and doors to an occupancy grid by data-driven MCMC.

    Parameters
    ----------
    occupancy : (H, W) int8
        -1 unknown, 0..100 occupancy percent; row 0 is the lowest y (GridLayer order).
    resolution_m : float
        Metres per cell.
    origin_xy_m : (float, float)
        Map position of cell (0, 0)'s corner.
    settings : FloorPlanSettings, optional
    start : World, optional
        A previous world to warm-start from (a grown map), in cells of this map's frame (:func:`make_frame`
        with ``angle_rad``; :func:`~services.floor_plan.frame.carry` moves a world there); units that no
        longer fit are dropped.
    angle_rad : float, optional
        The direction of the walls to explain along (radians, x = column, y = row); by default the map's
        dominant orientation, or 0 when that is within ``settings.min_turn_rad`` of the axes.
    trajectory_xy_m : (N, 2) float, optional
        Robot positions (map metres) where a trajectory is known (a bag, live traffic): the places a robot
        passed that the world leaves unexplained seed unit candidates (the robot-position detector).

    Raises
    ------
    FloorPlanError
        Maps that are not 2-D, too small, without free cells; nonsensical settings.
    """
    s = settings or FloorPlanSettings()
    if not math.isfinite(resolution_m) or resolution_m <= 0:
        raise FloorPlanError(f"resolution must be a positive number of metres, got {resolution_m}")
    classes_map = classify_map(occupancy, occupied_percent=s.occupied_percent, free_percent=s.free_percent)
    traces = (np.zeros(classes_map.shape, np.bool_) if s.trace_max_m is None else
              beam_traces(classes_map, width_cells=_cells(s.trace_max_m, resolution_m)))
    fringe = (np.zeros(classes_map.shape, np.bool_) if s.fringe_m is None else
              wall_fringe(occupancy, classes_map == CellClass.FREE, depth_cells=_cells(s.fringe_m, resolution_m),
                          min_wall_cells=max(1, round(s.fringe_wall_m2 / resolution_m**2)),
                          inside_max_cells=round(s.fringe_inside_m2 / resolution_m**2),
                          inside_min_depth_cells=_cells(s.fringe_inside_depth_m, resolution_m)))
    classes_map[traces] = CellClass.UNKNOWN
    solid = _obstacles(classes_map, s, resolution_m)
    if s.wall_m is None:
        s = replace(s, wall_m=wall_thickness_cells(classes_map, obstacles=solid) * resolution_m)
    if angle_rad is None:
        angle_rad = dominant_angle(classes_map, min_angle_rad=s.min_turn_rad)
    frame = make_frame(classes_map.shape, angle_rad=angle_rad, origin_xy_m=origin_xy_m, resolution_m=resolution_m)
    classes = to_work(frame, classes_map, fill=CellClass.UNKNOWN)
    ks = kernel_settings(s, resolution_m)
    evidence = Evidence(classes)
    lines = wall_lines(classes, wall_cells=ks.wall_cells, min_length_cells=_cells(s.min_line_m, resolution_m))
    candidates = wbu_candidates(lines, evidence, wall_cells=ks.wall_cells, min_inner_cells=ks.min_inner_cells)
    proposer = Proposer(evidence, lines, ks, candidates)
    obstacles = to_work(frame, solid.astype(np.uint8), fill=0).astype(bool)
    blocks = to_work(frame, enclosed_blocks(solid).astype(np.uint8), fill=0).astype(bool)
    prior = ContextPrior(resolution_m=resolution_m, wall_cells=ks.wall_cells, settings=s.context)

    def chain_from(world: World) -> Chain:
        canvas = Canvas(classes, log_sensor_table(s.sensor_model), wall_cells=ks.wall_cells,
                        log_overlap=math.log(s.overlap_psi), obstacles=obstacles, blocks=blocks)
        return Chain(world, canvas, proposer, prior)

    first = 1
    world = World()
    if start is not None and start.units:
        world = World({u: r for u, r in start.units.items() if proposer.valid(r)}, set(), start.next_id)
        world.doors = {d for d in start.doors if len(world.door_units(d, ks.wall_cells)) == 2}
        first = s.warm_start_iteration
    positions = None
    if trajectory_xy_m is not None and len(trajectory_xy_m):
        xy = np.asarray(trajectory_xy_m, np.float64).reshape(-1, 2)
        rc = np.stack([(xy[:, 1] - origin_xy_m[1]) / resolution_m, (xy[:, 0] - origin_xy_m[0]) / resolution_m], axis=1)
        positions = np.unique(np.floor(points_to_work(frame, rc)).astype(np.int64), axis=0)
    result = _best_of_chains(chain_from, world, classes, s.chain, first_iteration=first, positions_rc=positions,
                             restarts=s.chain.restarts if first == 1 else 1)
    return describe(result.world, classes_map, frame=frame, settings=s, fringe=fringe, traces=traces,
                    log_posterior=result.log_posterior, iterations=result.iterations, accepted=result.accepted,
                    seconds=result.seconds, cpu_seconds=result.cpu_seconds)


_TIE_NATS = 1e-6
"""Log posteriors closer than this are equal (the chain's score is a sum of many increments)."""


def _best_of_chains(chain_from: Callable[[World], Chain], world: World, classes: npt.NDArray[np.uint8],
                    settings: ChainSettings, *, first_iteration: int, positions_rc: npt.NDArray[np.int64] | None,
                    restarts: int) -> ChainResult:
    """``restarts`` independent chains from ``world``; the result of the highest log posterior (an earlier chain's on a
    tie to the rounding of the incremental score). ``settings.max_seconds`` bounds them all together; iterations and
    seconds add up."""
    if restarts < 1:
        raise FloorPlanError(f"need at least one chain, got restarts {restarts}")
    runs: list[ChainResult] = []
    spent = 0.0
    for stream in range(restarts):
        if runs and spent >= settings.max_seconds:
            break
        runs.append(run_chain(chain_from(world.copy()), classes,
                              replace(settings, max_seconds=settings.max_seconds - spent),
                              first_iteration=first_iteration, positions_rc=positions_rc, stream=stream))
        spent += runs[-1].seconds
    best = runs[0]
    for run in runs[1:]:
        if run.log_posterior > best.log_posterior + _TIE_NATS:
            best = run
    return ChainResult(best.world, best.log_posterior, sum(r.iterations for r in runs), sum(r.accepted for r in runs),
                       sum(r.seconds for r in runs), sum(r.cpu_seconds for r in runs))


def describe(
    world: World, classes_map: npt.NDArray[np.uint8], *, frame: Frame, settings: FloorPlanSettings,
    fringe: npt.NDArray[np.bool_] | None = None, traces: npt.NDArray[np.bool_] | None = None,
    log_posterior: float = float("nan"), iterations: int = 0, accepted: int = 0, seconds: float = 0.0,
    cpu_seconds: float = 0.0,
) -> FloorPlan:
    """A world (cells of ``frame``) as units, doors, types and K(W,M) in map coordinates; ``fringe`` (map cells) is
    left out of the label images (none by default); ``traces`` (map cells ``classes_map`` reads unknown, laser beams'
    traces) are free to the rooms."""
    resolution_m, origin_xy_m = frame.resolution_m, frame.origin_xy_m
    t = kernel_settings(settings, resolution_m).wall_cells
    ox, oy = origin_xy_m

    def xy(r: float, c: float) -> tuple[float, float]:
        return round(ox + c * resolution_m, 4), round(oy + r * resolution_m, 4)

    def work_xy(*rc: tuple[float, float]) -> list[tuple[float, float]]:
        back = points_to_map(frame, np.array(rc, np.float64))
        return [xy(float(r), float(c)) for r, c in back]

    prior = ContextPrior(resolution_m=resolution_m, wall_cells=t, settings=settings.context)
    sem = prior.semantics(world)
    units = []
    for uid, r in sorted(world.units.items()):
        # the polygon runs along the middle of the walls
        a0, a1 = r.r0 + t / 2, r.r1 + 1 - t / 2
        b0, b1 = r.c0 + t / 2, r.c1 + 1 - t / 2
        corners = work_xy((a0, b0), (a0, b1), (a1, b1), (a1, b0))
        ring = (*corners, corners[0])
        area = (a1 - a0) * (b1 - b0) * resolution_m**2
        units.append(Unit(uid, r, ring, sem[uid].unit_type, sem[uid].probability, area))
    doors = []
    for d in sorted(world.doors):
        holders = world.door_units(d, t)
        if len(holders) != 2:
            continue
        if d.rows > d.cols:  # along rows: a vertical wall
            c = d.c0 + d.cols / 2
            p, q = work_xy((d.r0, c), (d.r1 + 1, c))
            seg = (p, q)
            width = d.rows * resolution_m
        else:
            rr = d.r0 + d.rows / 2
            p, q = work_xy((rr, d.c0), (rr, d.c1 + 1))
            seg = (p, q)
            width = d.cols * resolution_m
        doors.append(Door(d, seg, (holders[0], holders[1]), width))
    traces = np.zeros(classes_map.shape, np.bool_) if traces is None else traces
    classes_work = to_work(frame, classes_map, fill=CellClass.UNKNOWN)
    lines = _slant_lines(classes_work, settings, resolution_m)
    rooms, room_cells = _rooms(world, classes_map, traces, lines, {u: m.unit_type for u, m in sem.items()},
                               frame=frame, settings=settings, wall_cells=t)
    ids = sorted(world.units)
    adjacency = [(a, b) for i, a in enumerate(ids) for b in ids[i + 1:]
                 if shared_band(world.units[a], world.units[b], t) is not None]
    solid = _obstacles(classes_map, settings, resolution_m)
    seed_world = to_map(frame, render(world, frame.shape, wall_cells=t), fill=CellClass.UNKNOWN)
    k_units = cell_prediction_rate(classes_map, np.where(solid, np.uint8(CellClass.WALL), seed_world))
    log_table = log_sensor_table(settings.sensor_model)
    walls: dict[int, tuple[tuple[Segment, ...], ...]] = {}
    slants: dict[int, tuple[Slant, ...]] = {}
    wall_segments = 0
    cw = seed_world
    if settings.wall_shift_m is not None:
        fitted = fit_walls(world, classes_work, log_table, wall_cells=t,
                           fixed=to_work(frame, solid.astype(np.uint8), fill=0).astype(bool),
                           max_shift=round(settings.wall_shift_m / resolution_m),
                           max_thickness=t + round(settings.wall_extra_m / resolution_m),
                           log_cost=settings.wall_log_cost, segment_cells=_cells(settings.wall_segment_m, resolution_m),
                           lines=None if settings.slant_min_angle_rad is None else slanted(
                               lines, settings.slant_min_angle_rad))
        cw = to_map(frame, fitted.classes_world, fill=CellClass.UNKNOWN)
        walls, wall_segments = fitted.segments, fitted.fitted
        slants = {uid: cuts for uid, cuts in fitted.slants.items() if cuts}
    cw = np.where(solid, np.uint8(CellClass.WALL), cw).astype(np.uint8)
    clutter = exterior = 0
    if settings.clutter_max_m2 is not None:
        max_cells = max(1, round(settings.clutter_max_m2 / resolution_m**2))
        found = explain_clutter(classes_map, cw, log_table, max_cells=max_cells, log_cost=settings.clutter_log_cost)
        outside = explain_exterior(classes_map, found.classes_world, log_table, max_cells=max_cells,
                                   log_cost=settings.clutter_log_cost)
        cw, clutter, exterior = outside.classes_world, found.drawn, outside.drawn
    contours, hierarchy = cv2.findContours(solid.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)

    def ring_of(contour: npt.NDArray[np.integer[Any]] | cv2.typing.MatLike) -> tuple[tuple[float, float], ...]:
        pts = cv2.approxPolyDP(contour, 1.0, True).reshape(-1, 2)
        ring = [xy(float(y) + 0.5, float(x) + 0.5) for x, y in pts]
        return (*ring, ring[0]) if len(ring) >= 3 else ()

    rings: list[tuple[tuple[tuple[float, float], ...], ...]] = []
    standing: list[bool] = []
    blocks = enclosed_blocks(solid)
    for i, contour in enumerate(contours):
        if hierarchy[0][i][3] != -1:
            continue  # a hole: it goes with its outer boundary
        outer = ring_of(contour)
        holes = [ring_of(contours[j]) for j in range(len(contours)) if hierarchy[0][j][3] == i]
        if outer:
            rings.append((outer, *(h for h in holes if h)))
            x, y = contour.reshape(-1, 2)[0]
            standing.append(bool(blocks[y, x]))
    return FloorPlan(world, units, doors, adjacency, rooms, room_cells, rings, standing, classes_map, cw,
                     cell_prediction_rate(classes_map, cw), k_units, clutter, walls, wall_segments, slants, exterior,
                     log_posterior, iterations, accepted,
                     seconds, cpu_seconds, resolution_m, origin_xy_m, frame,
                     np.zeros(classes_map.shape, np.bool_) if fringe is None else fringe, traces,
                     None if settings.furniture is None else furniture(
                         (classes_map != CellClass.FREE) & ~traces, resolution_m=resolution_m,
                         settings=settings.furniture), _insides(classes_map, traces, settings, resolution_m),
                     None if settings.furniture is None or settings.furniture.pocket_max_m2 <= 0 else furniture_pockets(
                         classes_map == CellClass.UNKNOWN, traces, resolution_m=resolution_m,
                         settings=settings.furniture),
                     1 if settings.furniture is None else _cells(settings.furniture.pocket_reach_m, resolution_m),
                     None if settings.rooms.free_piece_min_m2 is None else max(
                         1, round(settings.rooms.free_piece_min_m2 / resolution_m**2)),
                     _cells(settings.rooms.free_piece_reach_m, resolution_m))


def _insides(classes_map: npt.NDArray[np.uint8], traces: npt.NDArray[np.bool_], settings: FloorPlanSettings,
             resolution_m: float) -> npt.NDArray[np.uint8] | None:
    """The insides of furniture and the furniture round them (``FloorPlan.insides``), or None where there are none."""
    if settings.fringe_inside_m2 <= 0:
        return None
    free = (classes_map == CellClass.FREE) | traces
    inside = furniture_insides(free, max_cells=round(settings.fringe_inside_m2 / resolution_m**2),
                               min_depth_cells=_cells(settings.fringe_inside_depth_m, resolution_m))
    if not inside.any():
        return None
    return furniture_reach(inside, ~free, reach_cells=_cells(settings.fringe_inside_reach_m, resolution_m))


def _slant_lines(classes_work: npt.NDArray[np.uint8], settings: FloorPlanSettings,
                 resolution_m: float) -> npt.NDArray[np.float64]:
    """The map's straight wall lines (cells of the working frame) the slanted walls and the rooms' re-cut use."""
    if settings.slant_line_m is None:
        return np.zeros((0, 4))
    return wall_line_segments(classes_work, min_length_cells=_cells(settings.slant_line_m, resolution_m),
                              max_gap_cells=round(settings.slant_gap_m / resolution_m),
                              wall_share=settings.slant_wall_share)


def _rooms(world: World, classes_map: npt.NDArray[np.uint8], traces: npt.NDArray[np.bool_],
           lines: npt.NDArray[np.float64], types: dict[int, UnitType], *, frame: Frame, settings: FloorPlanSettings,
           wall_cells: int) -> tuple[list[Room], npt.NDArray[np.int32]]:
    """The room level of a world (:mod:`services.floor_plan.rooms`, re-cut along slanted walls) and its cells."""
    seen_work = to_work(frame, np.where(traces, np.uint8(CellClass.FREE), classes_map), fill=CellClass.UNKNOWN)
    rooms, cells = split_at_slanted_walls(
        group_rooms(world, seen_work, types, wall_cells=wall_cells, resolution_m=frame.resolution_m,
                    settings=settings.rooms),
        world, seen_work, lines, resolution_m=frame.resolution_m, reach_m=0.5 * settings.slant_gap_m,
        settings=settings.rooms)
    free = seen_work == CellClass.FREE
    fronts = open_fronts(free, resolution_m=frame.resolution_m, settings=settings.rooms)
    return split_at_fronts(rooms, cells, world, free, fronts, resolution_m=frame.resolution_m, settings=settings.rooms)


def unit_labels(plan: FloorPlan) -> npt.NDArray[np.int32]:
    """A label image (GridLayer order, map cells): each unit's id on the map's free cells, as the grid
    decomposition's segments cover them: inside a unit its id (where units overlap the smaller one wins), and
    every free cell the world leaves unexplained the id of the unit nearest to it through free space.
    """
    items = sorted(((u.rect, u.id) for u in plan.units), key=lambda item: -item[0].rows * item[0].cols)
    return _labels(plan, items)


def room_labels(plan: FloorPlan) -> npt.NDArray[np.int32]:
    """A label image like :func:`unit_labels` with one id per room (1..R in the order of ``plan.rooms``): each
    room's free cells (``plan.room_cells``), grown through free space to the free cells no room holds, the
    furniture standing in it (``plan.furniture``), the insides of furniture, with the room nearest to them through
    the furniture (``plan.insides``), and the furniture the map draws in its unknown grey against a wall, with the one
    room touching it or within reach of it (``plan.pockets``); then each piece of free space no room reaches through
    free space (``plan.free_piece_min_cells`` or more) with the one room within ``plan.free_piece_reach_cells``."""
    cells = to_map(plan.frame, plan.room_cells.astype(np.float32), fill=0.0).astype(np.int32)
    free = (plan.classes_map == CellClass.FREE) | plan.traces
    out = fill_free(cells, free)
    out[plan.fringe] = 0
    out = out if plan.furniture is None else label_furniture(out, plan.furniture)
    out = out if plan.insides is None else join_insides(out, plan.insides)
    if plan.pockets is not None:
        # a pocket takes the one room touching it; one no room touches (a cupboard drawn with a dark outline), the
        # one room within reach
        pockets = plan.pockets & (out == 0)
        touched = label_furniture(out, pockets)
        out = label_furniture(touched, pockets & (touched == 0), reach_cells=plan.pocket_reach_cells)
    if plan.free_piece_min_cells is None:
        return out
    return label_furniture(out, cut_off_free(out, free & ~plan.fringe, min_cells=plan.free_piece_min_cells),
                           reach_cells=plan.free_piece_reach_cells)


def _labels(plan: FloorPlan, items: list[tuple[Rect, int]]) -> npt.NDArray[np.int32]:
    """Each rectangle's id painted in order (cells of the plan's frame), on the map's free cells, grown through
    free space to the free cells none covers."""
    work = np.zeros(plan.frame.shape, np.float32)  # ids as float32 (exact below 2**24) so OpenCV can turn them
    for r, k in items:
        work[r.r0 : r.r1 + 1, r.c0 : r.c1 + 1] = k
    free = (plan.classes_map == CellClass.FREE) | plan.traces
    out = fill_free(to_map(plan.frame, work, fill=0.0).astype(np.int32), free)
    out[plan.fringe] = 0
    return out
