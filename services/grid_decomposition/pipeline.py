"""The whole decomposition of an occupancy grid: lines, cells, cogency, places, labels and regions."""

from __future__ import annotations

import enum
import importlib
import logging
import math
from collections.abc import Callable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, TypeVar

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import (
    Components,
    MaskCounts,
    components,
    label_counts,
    label_max,
    label_sums,
    lookup,
    unique_inverse,
)
from services.grid_decomposition.cleaning import clean_occupancy
from services.grid_decomposition.cogency import EdgeCogency, edge_cogency, wall_evidence
from services.grid_decomposition.continuity import RegionPrior, keep_regions
from services.grid_decomposition.corridor_pieces import join_corridor_pieces
from services.grid_decomposition.corridors import part_rooms_from_corridors
from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.faces import face_geometry
from services.grid_decomposition.fans import split_fans
from services.grid_decomposition.labelling import FaceLabels, assign_labels, evidence_labels, face_categories
from services.grid_decomposition.loose import (
    fill_between,
    fill_enclosed,
    fill_near,
    give_far_pieces,
    join_and_fill_loose,
    join_ray_pieces,
)
from services.grid_decomposition.openings import join_unseen_openings, join_unseen_passages
from services.grid_decomposition.orientations import Gradients, dominant_orientations, oriented_gradients
from services.grid_decomposition.places import categorize_places
from services.grid_decomposition.racks import (
    RackLayout,
    combine,
    face_places,
    find_racks_by_region,
    floor_objects,
    place_segments,
    pocket_merges,
)
from services.grid_decomposition.radiogram import Line, line_offsets, radiogram
from services.grid_decomposition.regions import (
    RegionInfo,
    face_regions,
    link_components,
    region_topology,
    road_networks,
    warehouse_floors,
)
from services.grid_decomposition.rooms import (
    free_standing,
    furniture,
    inside_furniture,
    join_furnished_pieces,
    segment_rooms,
    wall_furniture,
)
from services.grid_decomposition.segments import (
    border_closure,
    fill_bytes_from_neighbours,
    fill_from_neighbours,
    merge_passages,
    segment_image,
)
from services.grid_decomposition.shelves import find_shelf_banks, majority_faces
from services.grid_decomposition.short_walls import split_at_short_walls
from services.grid_decomposition.standing import join_across_open_lines, join_free_standing_ends
from services.grid_decomposition.subdivision import LineGroup, Subdivision, subdivide
from services.grid_decomposition.texture import segment_texture_regions
from shared.opencv_threads import opencv_on_one_thread
from shared.vocabulary import PlaceLabel

if TYPE_CHECKING:  # networkx is imported by the steps that build graphs, when first needed
    import networkx as nx

logger = logging.getLogger(__name__)
_T = TypeVar("_T")

FREE_PERCENT = 25
OCCUPIED_PERCENT = 65
_REGION_CORE_M = 1.0
_POCKET_MAX_M2 = 6.0  # a room this small among pallets, open to an open area, is floor between them
_MIN_PASSAGE_M = 0.3  # regions touching along less than this are not linked by their pixels
# doors side by side with posts between them lie in a wall: the runs beside them are longer than a wall crossing the
# line is thick (read with the lines' 0.1 m tolerance each side, a 0.5 m thick wall is a 0.7 m run)
_POST_WALL_M = 0.75
_WALL_MAX_THICKNESS_M = 0.6  # a wall beside a doorway is at most this thick (find_doorways' max_wall_thickness_m)
# ... and a post is one the line passes through, not the rim of its tolerance disc (one sample at the line's 0.1 m)
_POST_MIN_RUN_M = 0.1
_PASSAGE_MIN_BORDER_M = 0.5  # a strip between regions borders each of them along at least this ...
_PASSAGE_MAX_WIDTH_M = 1.0  # ... and is nowhere wider than this (a cut strip a door deep; a room is wider)
_FAN_GAP_M = 0.5  # rays this close are one fan (the cleaning bridges the unknown between them: twice its fan gap)
_DOT_REACH_M = 1.0  # a dot walls close in takes the region it sees this near in line (else reaches this near)
_FAR_PIECE_M = 3.0  # a piece of a region this far from its body is dots of another room's rays ...
_FAR_PIECE_REACH_M = 2.0  # ... given to the region that reaches it this near through cells not occupied
_SEEN_WALL_M = 0.15  # a border of a region of rays with no occupied cell this near the laser saw through
_RAY_BORDER_MIN_M = 0.25  # ... along at least this (a corner or a ray's end is no border)
# imported by the steps when first needed (about 0.9 s, once a process), loaded by decompose on its
# second thread while the first steps run; all on one thread: two threads importing one package
# at once can deadlock on its partly loaded modules. The line search needs the first batch; scikit-learn
# (the place categories on that thread, the texture regions when a map has several) is loaded after it,
# while the line search runs; networkx (only the region graph, at the end, needs it) later still
_STEP_MODULES = ("scipy.ndimage", "scipy.optimize", "scipy.signal", "scipy.stats")
_CLUSTERING_MODULES = ("sklearn.cluster", "sklearn.decomposition", "sklearn.preprocessing")


class Resolution(enum.Enum):
    """Which line set decomposes the map (paper B: peak amplitude and width set the resolution)."""

    COARSE = "coarse"
    FINE = "fine"


@dataclass(frozen=True)
class Decomposition:
    """Everything :func:`decompose` found, in grid order (row 0 = lowest y).

    Attributes
    ----------
    labels : (H, W) uint8
        :class:`PlaceLabel` code per pixel, 0 off free space.
    segments : (H, W) int32
        Region id per pixel, 0 where no region.
    regions : dict[int, RegionInfo]
    topology : networkx.Graph
        Regions linked with attribute ``connection``.
    line_groups : tuple[LineGroup, ...]
        Lines per texture region (all lines, ``coarse`` flag set); the decomposition used
        ``resolution``.
    subdivision : Subdivision
        Faces are the free parts of the polygonal cells.
    cogency : EdgeCogency
    face_labels : FaceLabels
    texture_regions : (H, W) int32
    resolution : Resolution
    resolution_m : float
    origin_xy_m : tuple[float, float]
    rack_rows_px : (R, 4, 2) float64
        Corners (x = column, y = row) of every rack row found (:func:`find_racks`), pixels.
    """

    labels: npt.NDArray[np.uint8]
    segments: npt.NDArray[np.int32]
    regions: dict[int, RegionInfo]
    topology: nx.Graph
    line_groups: tuple[LineGroup, ...]
    subdivision: Subdivision
    cogency: EdgeCogency
    face_labels: FaceLabels
    texture_regions: npt.NDArray[np.int32]
    resolution: Resolution
    resolution_m: float
    origin_xy_m: tuple[float, float]
    rack_rows_px: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4, 2)))


def _check(occupancy: npt.NDArray[np.integer], resolution_m: float) -> npt.NDArray[np.int16]:
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or min(occ.shape, default=0) < 2:
        raise DecompositionError(f"occupancy must be a 2-D grid of at least 2 x 2 cells, got shape {occ.shape}")
    if not np.issubdtype(occ.dtype, np.integer):
        raise DecompositionError(f"occupancy must be integer (-1 unknown, 0..100), got dtype {occ.dtype}")
    if not (math.isfinite(resolution_m) and resolution_m > 0):
        raise DecompositionError(f"resolution_m must be a positive number of metres, got {resolution_m}")
    occ16 = occ.astype(np.int16)
    if occ16.min() < -1 or occ16.max() > 100:
        raise DecompositionError(f"occupancy values must be -1 or 0..100, got {occ16.min()}..{occ16.max()}")
    if not np.any(occ16.view(np.uint16) < FREE_PERCENT):  # 0 <= value < FREE_PERCENT (-1 is 65535 unsigned)
        raise DecompositionError("occupancy has no free cell: nothing to decompose")
    return occ16


def _masked(gradients: Gradients, mask: npt.NDArray[np.bool_]) -> Gradients:
    keep = mask[gradients.rows, gradients.cols]
    return Gradients(
        gradients.shape,
        gradients.rows[keep],
        gradients.cols[keep],
        gradients.magnitude[keep],
        gradients.direction[keep],
    )


def _families(angles: npt.NDArray[np.float64], tolerance_rad: float) -> list[list[float]]:
    """Orientations grouped into orthogonal families (angle modulo 90 degrees)."""
    families: list[list[float]] = []
    for a in angles:
        folded = a % (math.pi / 2)
        for fam in families:
            d = abs((fam[0] % (math.pi / 2)) - folded)
            if min(d, math.pi / 2 - d) < tolerance_rad:
                fam.append(float(a))
                break
        else:
            families.append([float(a)])
    return families


def _lines(
    gradients: Gradients,
    structure: Gradients,
    mask: npt.NDArray[np.bool_] | None,
    resolution_m: float,
) -> dict[float, list[Line]]:
    """Lines per dominant orientation inside ``mask``: directions from ``structure``, radiograms from all.

    A texture region's directions come from its structure at least ``_REGION_CORE_M`` inside it, so
    a sliver of a neighbouring region's wall along its border adds no direction of its own.
    """
    grads = gradients if mask is None else _masked(gradients, mask)
    struct = structure if mask is None else _masked(structure, _core(mask, round(_REGION_CORE_M / resolution_m)))
    if struct.magnitude.size < 0.05 * max(grads.magnitude.size, 1):
        struct = grads
    return {
        float(a): line_offsets(radiogram(grads, float(a)), resolution_m=resolution_m)
        for a in dominant_orientations(struct)
    }


def _core(mask: npt.NDArray[np.bool_], depth_px: int) -> npt.NDArray[np.bool_]:
    """Pixels of ``mask`` at least ``depth_px`` from its outside (all of it if nothing is that deep)."""
    inner = cv2.distanceTransform(np.pad(mask, 1).astype(np.uint8), cv2.DIST_L2, 3)[1:-1, 1:-1] >= depth_px
    return inner if inner.any() else mask


def _structure(obstacle: Components, min_area_px: int) -> npt.NDArray[np.bool_]:
    """Pixels near obstacle components of at least ``min_area_px`` (walls, blocks), not furniture or uprights."""
    big = obstacle.stats[:, cv2.CC_STAT_AREA] >= min_area_px
    big[0] = False
    return np.asarray(cv2.dilate(obstacle.spread(big.view(np.uint8)), np.ones((5, 5), np.uint8)), dtype=bool)


def _texture_count(lines: dict[float, list[Line]]) -> int:
    """Number of texture regions: orthogonal orientation families with substantial line support."""
    families = _families(np.array(list(lines)), math.radians(5.0))
    if len(families) < 2:
        return 1
    support = [sum(ln.support_m for a in fam for ln in lines[a] if ln.coarse) for fam in families]
    strong = [s for s in support if s >= 0.1 * max(support)]
    return max(1, len(strong))


def _clearance(free: npt.NDArray[np.bool_]) -> npt.NDArray[np.float32]:
    """Distance of every free pixel to the nearest obstacle, pixels (0 off free space)."""
    return np.asarray(cv2.distanceTransform(free.astype(np.uint8), cv2.DIST_L2, 3), dtype=np.float32)


def _elongation(
    component: npt.NDArray[np.int64],
    face_image: npt.NDArray[np.int32],
    dist: npt.NDArray[np.float32],
    resolution_m: float,
) -> npt.NDArray[np.float64]:
    """Area / clearance^2 of each component (clearance = twice the largest distance ``dist`` to an obstacle)."""
    n = int(component.max()) + 1
    # per face first, then per component (a face's pixels all lie in its component)
    face_width, face_area = label_max(face_image, dist, component.size)
    width = np.zeros(n, dtype=np.float32)
    np.maximum.at(width, component, face_width)
    width[0] = 0.0
    area = np.bincount(component, weights=face_area, minlength=n).astype(np.float64)
    elongation: npt.NDArray[np.float64] = area / np.maximum(2.0 * width.astype(np.float64), 1.0) ** 2
    return elongation


def _face_angles(sub: Subdivision, groups: list[LineGroup]) -> npt.NDArray[np.float64]:
    """Direction of each face's cutting lines: the best-supported line direction of the group holding most of it."""
    n = sub.n_faces + 1
    angle = np.zeros(n)
    best = np.zeros(n, dtype=np.int64)
    for group in groups:
        if not group.lines:
            continue
        support: dict[float, float] = {}
        for ln in group.lines:
            support[ln.angle_rad] = support.get(ln.angle_rad, 0.0) + ln.support_m
        main = max(support, key=lambda a: support[a])
        everywhere, inside = label_counts(sub.face_image, n, group.mask)
        count = everywhere if group.mask is None else inside
        more = count > best
        angle[more], best[more] = main, count[more]
    return angle


def decompose(
    occupancy: npt.NDArray[np.integer],
    *,
    resolution_m: float,
    origin_xy_m: tuple[float, float] = (0.0, 0.0),
    resolution: Resolution = Resolution.COARSE,
    n_texture_regions: int | None = None,
    n_categories: int = 8,
    label_overrides: Mapping[int, PlaceLabel] | None = None,
    door_max_width_m: float = 2.0,
    cut_max_width_m: float = 2.5,
    wall_min_length_m: float = 0.5,
    door_widening_m: float = 0.3,
    door_max_depth_m: float = 1.0,
    corridor_length_m: float = 2.0,
    wall_tolerance_m: float = 0.1,
    island_max_extent_m: float = 2.0,
    island_min_clearance_m: float = 0.3,
    desk_max_extent_m: float = 4.5,
    face_disparity_threshold: float = 0.5,
    edge_occupancy_threshold: float = 0.5,
    min_region_area_m2: float = 0.3,
    structure_min_area_m2: float = 0.5,
    neck_half_width_m: float = 0.5,
    room_min_area_m2: float = 1.5,
    clean: bool = True,
    streak_reach_m: float = 2.0,
    fan_max_neck_m: float = 1.2,
    known_places: RackLayout | None = None,
    prior: RegionPrior | None = None,
    settled_max_changed_share: float = 0.2,
    first_seen_room_max_m2: float = 16.0,
    first_seen_piece_min_m2: float = 2.5,
    corridor_min_region_m2: float = 100.0,
    short_wall_min_m: float = 3.0,
    corridor_pieces: bool = True,
    corridor_beyond_min_m2: float = 1.5,
    rejoin_room_pieces: bool = True,
    inside_furniture_max_m2: float = 1.5,
    passage_max_m2: float = 3.0,
    unseen_opening_m: float = 0.75,
    enclosed_dots_m: float = 5.0,
    free_standing_ends: bool = True,
    block_max_run_m: float = 1.5,
    seed: int = 0,
) -> Decomposition:
    """Decompose an occupancy grid into labelled regions (papers B and C plus doorway closing).

    Parameters
    ----------
    occupancy : (H, W) integer
        -1 unknown, 0..100 occupancy percent; row 0 = lowest y (GridLayer order). Free is below
        25, occupied above 65; uncertain cells count as obstacles for lines and ray casting.
    resolution_m : float
        Metres per cell.
    origin_xy_m : (float, float)
        Map coordinates of the lower-left corner of cell (0, 0), metres.
    resolution : Resolution
        Coarse (strong, narrow radiogram peaks only) or fine line set.
    n_texture_regions : int, optional
        Regions of different pattern (Gabor segmentation); ``None`` = as many as orthogonal
        orientation families with substantial support.
    n_categories : int
        k of the k-means place categorisation.
    label_overrides : mapping, optional
        Place category -> :class:`PlaceLabel`, replacing the automatic assignment.
    door_max_width_m, cut_max_width_m, wall_min_length_m, wall_tolerance_m, door_widening_m, door_max_depth_m : float
        Along lines, doorways up to ``door_max_width_m`` wide: gaps between wall runs of at least
        ``wall_min_length_m`` are closed when the free space behind them widens by
        ``door_widening_m`` on both sides within ``door_max_depth_m`` of the line (a corridor or a
        passage between blocks does not); walls within ``wall_tolerance_m`` of a line are on it.
        Off the lines, doorways up to ``cut_max_width_m`` wide are found from the free space itself
        (:func:`~services.grid_decomposition.doorways.find_doorways`, same widening). On real maps
        the gaps between furniture along a line closed as doors up to 2.5 m and cut furnished
        rooms apart; 2.0 m keeps the ipa doors.
    corridor_length_m : float
        A gap across a corridor is no doorway, along a line or off it, when the corridor goes on
        for this long on both sides as a band about as wide as the gap: beside an office door
        the corridor seems to widen (:func:`~services.grid_decomposition.doorways.across_a_corridor`);
        0 turns it off.
    island_max_extent_m, island_min_clearance_m : float
        Obstacles standing free in a room (off the map border, at most ``island_max_extent_m``
        across, at least ``island_min_clearance_m`` from every other obstacle: a desk cluster, a
        table with its chairs) are no wall along the lines: a gap between one and a wall is no
        doorway (:func:`~services.grid_decomposition.rooms.free_standing`); 0 turns it off.
    desk_max_extent_m : float
        Pieces of a room that only furniture separates (desk clusters, tables and chairs standing
        free, solid and compact, up to this size across) join when together they are room-shaped
        (:func:`~services.grid_decomposition.basins.join_furnished_groups`); 0 turns it off.
    face_disparity_threshold, edge_occupancy_threshold : float
        t1, t2 of the cogency test.
    min_region_area_m2 : float
        Smaller pieces of free space join a neighbouring region.
    neck_half_width_m : float
        A room whose free space falls apart when shrunk by this half-width is split into the
        rooms its necks join (:func:`split_at_necks`); 0 turns it off.
    room_min_area_m2 : float
        Regions off warehouse floors smaller than this (door slivers, strips between close lines)
        join the neighbour they share the longest border with
        (:func:`~services.grid_decomposition.rooms.segment_rooms`: rooms off warehouse floors
        are face regions joined across open borders, with their furniture, cut at doorways). Such
        regions that touch no other and lie within 0.5 m of each other through unknown space (pieces
        of one fan of laser rays) join each other
        (:func:`~services.grid_decomposition.loose.join_isolated_pieces`); a region that touches no other
        (a room seen alone through the gaps of its walls) takes the free cells no region holds within
        0.5 m of it, the dots of its rays (:func:`~services.grid_decomposition.loose.fill_lone_regions`).
    structure_min_area_m2 : float
        Dominant orientations come from the edges of obstacle components at least this large
        (walls, blocks, unknown space); furniture and rack uprights, whose blob edges point every
        way and whose lattices line up along diagonals, still vote in the radiograms.
    clean : bool
        Clean the map first (:func:`~services.grid_decomposition.cleaning.clean_occupancy`: wall
        fringes, specks, laser streaks): the decomposition sees the cleaned map; the streaks it
        took out are labelled with the region they grow from, up to ``streak_reach_m`` from it
        (a wall fringe is never labelled).
    streak_reach_m : float
        See ``clean``.
    fan_max_neck_m : float
        A room (a fan of rays, or floor) leaving a room region through a neck at most this wide is a
        room of its own (:func:`~services.grid_decomposition.fans.split_fans`), in the new decomposition and again
        in the regions the ``prior`` kept; a region under a hall's size loses only fans of laser rays (the
        cleaning's rays and streaks), never its own floor beyond a neck; a hall also loses a room of rays behind a
        door up to ``door_max_width_m`` wide, cut at the door's line; floor too shallow for a room just inside a door,
        beside such a room of rays, is that room's; 0 turns it off.
    short_wall_min_m : float
        After the rooms are parted from their corridors, a room region of at least
        ``corridor_min_region_m2`` parts along a wall at least this long that stops short of the
        region's edge (:func:`~services.grid_decomposition.short_walls.split_at_short_walls`: two rooms
        the map's partial wall leaves one region); 0 turns it off.
    corridor_pieces : bool
        A corridor band (parallel lines with walls on both sides) that the room stage cut in pieces is one
        region again, and the rooms that leak into its strip part from it
        (:func:`~services.grid_decomposition.corridor_pieces.join_corridor_pieces`).
    corridor_beyond_min_m2 : float
        With ``corridor_pieces``, the corridor's own region parts what it holds beyond a band's side line and
        along its run when that is at least this large and reaches away from the band at least its front's length:
        a room seen through a gap in the corridor's wall that no doorway closed. Such rooms stay apart from the
        corridor when furnished pieces join again; 0 turns it off.
    rejoin_room_pieces : bool
        After the corridor steps, pieces of one furnished room join again as the room stage joins them
        (:func:`~services.grid_decomposition.rooms.join_furnished_pieces`): pieces the room stage left apart because
        the corridor was still in the region beside them (its union with them an L rather than a T).
    inside_furniture_max_m2 : float
        A region smaller than this that touches no other and that one obstacle island at most 3 m across encloses
        (free space inside a cupboard or a hollow pillar) joins the region nearest to it within 1 m
        (:func:`~services.grid_decomposition.rooms.inside_furniture`); 0 turns it off.
    passage_max_m2 : float
        A region smaller than this and nowhere wider than 1 m that borders two or more others over at least 0.5 m
        each, along a third of its outline or more (the strip between two cuts across a room, its long sides on the
        cuts), joins the one it shares the longest border with
        (:func:`~services.grid_decomposition.segments.merge_passages`); 0 turns it off.
    unseen_opening_m : float
        Two regions whose border is one straight cut at most ``cut_max_width_m`` long with no occupied cell within
        this distance of either end (from unknown space to unknown space: across a strip of laser rays, no doorway
        in a wall the laser saw) join (:func:`~services.grid_decomposition.openings.join_unseen_openings`); 0 turns
        it off. With ``passage_max_m2`` above 0 too, a piece smaller than that between two straight cuts (at least
        0.5 m each) whose floor's edge the laser hit along less than 0.5 m (cuts ending on bumps of the grey fringe
        of unseen walls) joins both its sides
        (:func:`~services.grid_decomposition.openings.join_unseen_passages`).
    enclosed_dots_m : float
        A free cell no region holds (a dot of a laser ray) looks along its row and column, four ways, to the first
        obstacle, doorway line or region cell; when three of the four meet one within this distance (it lies inside
        a room's walls, not beyond the building's outer wall), it takes the region whose floor it meets nearest
        within 1 m, else the region of the furniture or unseen pocket it meets nearest
        (:func:`~services.grid_decomposition.loose.fill_enclosed`); such a cell (streaks included) that meets no
        region so near in line takes the region that grows to it first within 1 m, through no obstacle or doorway
        line (:func:`~services.grid_decomposition.loose.fill_near`); 0 turns both off.
    free_standing_ends : bool
        On a room map, two regions whose border is longer than ``door_max_width_m`` and ends on an obstacle standing
        free on their floor (the laser's hits off every seen wall and off their line, the free space round them
        theirs), every other end on a seen wall, are one room: a doorway's jambs are walls' ends
        (:func:`~services.grid_decomposition.standing.join_free_standing_ends`).
    block_max_run_m : float
        A gap between a room's side wall (running straight past one end) and a block at the other (thicker than a
        wall, hit by the laser, ending along the gap within this: a cupboard or table standing out from the facing
        wall) is no doorway, on the lines and off them
        (:func:`~services.grid_decomposition.doorways.block_beside_a_wall`); 0 turns it off.
    known_places : RackLayout, optional
        Racks and aisles another stage knows on this grid (the pillar stage's bins and aisles,
        :func:`~services.grid_decomposition.known_racks.known_layout`): they are places as they say,
        before any the rack finder finds (which fills in the rest); a room touching a rack place is
        then the hall's open area.
    prior : RegionPrior, optional
        The previous decomposition of this map on this grid and the cells whose map content did not change
        since (:func:`~services.grid_decomposition.keys.region_prior`): a previous region with at most
        ``settled_max_changed_share`` of its cells changed keeps its unchanged cells, and the new region that
        continues it grows it (:func:`~services.grid_decomposition.continuity.keep_regions`), so a growing
        map's regions do not flicker where it did not change; settled regions this decomposition holds as one
        join when their border is wider than ``door_max_width_m`` and not narrow for the smaller
        (:func:`~services.grid_decomposition.continuity.joined_regions`). Racks, aisles and warehouse floors are
        the new decomposition's. A room behind a door that a kept region holds is parted from it as from a new one
        (``fan_max_neck_m``). Two neighbouring regions both seen for the first time (at most half of each in a
        previous region), each of at least ``first_seen_piece_min_m2`` and together of at most
        ``first_seen_room_max_m2`` (0: never), along a border at least ``door_max_width_m`` long, are one room
        the edge of what was seen cut at a door's line, and join (``continuity._join_first_seen``).
    seed : int
        Seed of the clusterings.

    Returns
    -------
    Decomposition

    Raises
    ------
    DecompositionError
        For grids that are not 2-D, too small, out of range, or without free space.
    """
    occ = _check(occupancy, resolution_m)
    surely_occupied = occ > OCCUPIED_PERCENT  # as mapped: the cleaning makes a faint trace across an aisle wall
    if n_categories < 1:
        raise DecompositionError(f"n_categories must be >= 1, got {n_categories}")
    # a second thread (the machine's second core: OpenCV and numpy calls release the GIL) loads the
    # steps' modules while this one cleans the map and finds its furniture and shelf banks, then
    # runs steps beside the line search (place categories, furniture against walls, free-standing
    # obstacles), the rack search and the cogency that do not need their results, and the region
    # graph beside the label image; each step gives the same result as run in turn. OpenCV's own pool is held to
    # one thread meanwhile: its second thread would only compete with ``beside`` for the second core
    with opencv_on_one_thread(), ThreadPoolExecutor(max_workers=1, thread_name_prefix="decompose") as beside:
        loaded = beside.submit(lambda: [importlib.import_module(name) for name in _STEP_MODULES])
        learned = beside.submit(lambda: [importlib.import_module(name) for name in _CLUSTERING_MODULES])
        streaks = rays = np.zeros(occ.shape, dtype=bool)
        if clean:
            cleaned, cleaning = clean_occupancy(occ, resolution_m=resolution_m)
            if np.any(cleaned.view(np.uint16) < FREE_PERCENT):  # a free cell left (-1 is 65535 unsigned)
                occ, streaks, rays = cleaned, cleaning.streaks, cleaning.rays
        free = occ.view(np.uint16) < FREE_PERCENT  # int16 -1..100: 0 <= value < FREE_PERCENT in one comparison
        known = occ >= 0
        obstacle = ~free
        occupied = occ > OCCUPIED_PERCENT  # -1 (unknown) is never above it

        def soon(fn: Callable[..., _T], *args: object, **kwargs: object) -> Future[_T]:
            """A step that needs no step library: on the other thread, or on this one (done) while that one is
            still loading the libraries (the first call in a process: this thread would wait for it)."""
            if learned.done():
                return beside.submit(fn, *args, **kwargs)
            here: Future[_T] = Future()
            here.set_result(fn(*args, **kwargs))
            return here

        # the distance to obstacles, for the rays and the elongation (on the other thread, in turn)
        clearance_job = soon(_clearance, free)
        places_job = beside.submit(
            lambda: categorize_places(
                obstacle, free, resolution_m=resolution_m, n_categories=n_categories, seed=seed,
                distance=clearance_job.result(),
            )
        )
        obstacle_parts = components(obstacle)  # labelled once: furniture, structure, free-standing obstacles
        standing_job = (
            soon(
                free_standing,
                obstacle,
                resolution_m=resolution_m,
                max_extent_m=island_max_extent_m,
                min_clearance_m=island_min_clearance_m,
                labelled=obstacle_parts,
            )
            if island_max_extent_m > 0
            else None
        )
        clutter = furniture(obstacle, resolution_m=resolution_m, labelled=obstacle_parts)
        occupied_parts = components(occupied)  # labelled once: shelf dashes, floor objects
        banks = find_shelf_banks(occupied, free, resolution_m=resolution_m, labelled=occupied_parts)
        gradients = oriented_gradients(obstacle)
        # the sides of laser rays are no walls: they would give the map directions of their own
        ray_sides = cv2.dilate(rays.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        structure = _masked(
            gradients, _structure(obstacle_parts, max(1, round(structure_min_area_m2 / resolution_m**2))) & ~ray_sides
        )
        loaded.result()  # the line search imports scipy.signal and scipy.ndimage
        global_lines = _lines(gradients, structure, None, resolution_m)
        n_tex = _texture_count(global_lines) if n_texture_regions is None else n_texture_regions
        if n_tex > 1:
            learned.result()  # the texture regions are clustered by scikit-learn
        texture = segment_texture_regions(obstacle, known, resolution_m=resolution_m, n_regions=n_tex, seed=seed)
        groups: list[LineGroup] = []
        for t in range(n_tex):
            mask = None if n_tex == 1 else texture == t
            if mask is not None and not mask.any():
                continue
            per_angle = global_lines if mask is None else _lines(gradients, structure, mask, resolution_m)
            groups.append(LineGroup(tuple(ln for lines in per_angle.values() for ln in lines), mask))
        used = [
            LineGroup(tuple(ln for ln in g.lines if resolution is Resolution.FINE or ln.coarse), g.mask) for g in groups
        ]
        logger.debug("texture regions %d, lines %s", n_tex, [len(g.lines) for g in used])
        # furniture and obstacles standing free in a room are no wall: no doorway ends on them
        walls = (occupied | ~known) & ~clutter
        if standing_job is not None:
            walls &= ~standing_job.result()
        side_by_side = np.zeros(occ.shape, dtype=bool)
        evidence_job = beside.submit(
            wall_evidence,
            walls,
            used,
            tolerance_px=max(1, round(wall_tolerance_m / resolution_m)),
            min_wall_px=max(1, round(wall_min_length_m / resolution_m)),
            max_door_px=max(1, round(door_max_width_m / resolution_m)),
            widening_px=max(1, round(door_widening_m / resolution_m)),
            max_depth_px=max(1, round(door_max_depth_m / resolution_m)),
            posts=clutter,
            post_wall_px=round(_POST_WALL_M / resolution_m),
            post_min_px=max(1, round(_POST_MIN_RUN_M / resolution_m)),
            corridor_length_px=round(corridor_length_m / resolution_m),
            hit=occupied,
            max_thickness_px=round(_WALL_MAX_THICKNESS_M / resolution_m),
            block_max_run_px=round(block_max_run_m / resolution_m),
            side_by_side_out=side_by_side,
        )
        known_obstacle = obstacle & known
        racks = find_racks_by_region(  # each texture region with its own directions
            known_obstacle, known, [(g.mask, sorted({ln.angle_rad for ln in g.lines})) for g in groups],
            resolution_m=resolution_m, solid=surely_occupied,
            # without uncertain cells (a trinary map) the known obstacles are the occupied cells, labelled already
            labelled=occupied_parts if np.array_equal(known_obstacle, occupied) else None,
        )
        if known_places is not None:
            if known_places.cells.shape != occ.shape:
                raise DecompositionError(f"known places of shape {known_places.cells.shape} on a grid of {occ.shape}")
            racks = combine([known_places, racks], occ.shape)
        sub = subdivide(used, occ.shape, domain=free, cuts=banks.outline | racks.outline)
        geometry_job = beside.submit(
            lambda: face_geometry(
                sub.face_image, sub.n_faces, obstacle, resolution_m=resolution_m, face_angle_rad=_face_angles(sub, used)
            )
        )
        wall, door = evidence_job.result()
        cog = edge_cogency(
            sub,
            occ,
            free,
            wall,
            door,
            face_disparity_threshold=face_disparity_threshold,
            edge_occupancy_threshold=edge_occupancy_threshold,
        )
        is_face = cog.face_free_px > 0
        connected = sub.edge_faces[~cog.cogent]
        component = link_components(sub.n_faces + 1, connected, is_face)
        elongation = _elongation(component, sub.face_image, clearance_job.result(), resolution_m)
        rack_place = face_places(sub.face_image, sub.n_faces, racks, free)  # while the other thread finds geometry
        geometry = geometry_job.result()
        found = evidence_labels(connected, geometry, component, elongation, cog.face_free_px, resolution_m=resolution_m)
        evidence = found.label.copy()
        # racks seen only as rows of dashes, and the aisles between them (no line lies on a dash end)
        evidence[majority_faces(sub.face_image, sub.n_faces, banks.storage, free)] = PlaceLabel.STORAGE.value
        evidence[majority_faces(sub.face_image, sub.n_faces, banks.aisle, free)] = PlaceLabel.CORRIDOR.value
        rows, cols, cats = places_job.result()
        face_cat = face_categories(sub.face_image, sub.n_faces, rows, cols, cats, n_categories)
        evidence = np.where(rack_place > 0, rack_place, evidence)
        face_labels = assign_labels(evidence, face_cat, cog.face_free_px, overrides=label_overrides)
        # regions come from the automatic labels: a person's overrides rename places, they do not
        # merge a warehouse's pallet cells and aisles into one region; a cross aisle one bay wide
        # keeps the place of a pallet cell in that structure (it is cut like one), named corridor
        cut_like_cells = np.where(found.off_pitch, PlaceLabel.STORAGE.value, evidence)
        automatic = assign_labels(cut_like_cells, face_cat, cog.face_free_px)
        # warehouse floors and road networks are split by their labels and left alone by the room stage
        roads = road_networks(  # (a fan of rays between unknown cells is no network of roads between blocks)
            sub, cog, component, cog.face_free_px, automatic.label, free=free, occupied=occupied, known=known, rays=rays
        )
        structured = warehouse_floors(component, cog.face_free_px, automatic.label) | roads
        region_of_face = face_regions(sub, cog, component, automatic.label, structured)
        # for the region graph, on the other thread (idle till the pairs) while this one draws the segments in long
        # numpy calls: the import holds the GIL, which the labelling steps before need between their short calls
        beside.submit(importlib.import_module, "networkx")
        segments = segment_image(
            sub.face_image, region_of_face, free, min_area_px=max(1, round(min_region_area_m2 / resolution_m**2))
        )
        # the room stage leaves racks alone (a flag per face first: one gather of the face image)
        floor_px = lookup(structured[component], sub.face_image) | (racks.cells > 0)
        on_floors = MaskCounts(floor_px)  # each step's segments' pixels and those on the floors (often few)
        # a rack hall (every segment on the floors): the room stage and the corridor steps are not run, nor their counts
        room_stage = not _on_floors_only(segments, floor_px)
        # furniture against walls (needed only after the room stage: on the other thread beside it, on a room map)
        against_walls_job = beside.submit(wall_furniture, obstacle, resolution_m=resolution_m) if room_stage else None
        cuts = np.zeros(occ.shape, dtype=bool)  # the doorways the room stage finds off the lines
        if room_stage:
            segments, cuts = segment_rooms(
                segments,
                clutter,
                floor_px,
                wall | door,
                resolution_m=resolution_m,
                door_max_width_m=cut_max_width_m,
                door_widening_m=door_widening_m,
                door_max_depth_m=door_max_depth_m,
                corridor_length_m=corridor_length_m,
                room_min_area_m2=room_min_area_m2,
                neck_half_width_m=neck_half_width_m,
                rays=rays,
                occupied=occupied,
                line_doors=door,
                desk_max_extent_m=desk_max_extent_m,
                block_max_run_m=block_max_run_m,
            )
        if corridor_min_region_m2 > 0 and room_stage:  # rooms open onto a corridor where the map never drew their wall
            size, on_floor = on_floors.counts(segments)
            candidates = (size >= corridor_min_region_m2 / resolution_m**2) & (on_floor == 0)
            candidates[0] = False
            if candidates.any():
                segments = part_rooms_from_corridors(
                    segments, occupied, [ln for g in used for ln in g.lines], candidates, resolution_m=resolution_m,
                    joinable=on_floor == 0,
                )
            if short_wall_min_m > 0:  # two rooms one region where the wall between them stops short
                size, on_floor = on_floors.counts(segments)
                candidates = (size >= corridor_min_region_m2 / resolution_m**2) & (on_floor == 0)
                candidates[0] = False
                segments = split_at_short_walls(
                    segments, occupied, [ln for g in used for ln in g.lines], candidates, resolution_m=resolution_m,
                    wall_min_m=short_wall_min_m,
                )
        beyond = None  # the rooms seen through a gap in a corridor's wall: apart from it
        if corridor_pieces and room_stage:  # a corridor cut where rooms open onto it is one region again
            # a region mostly off the warehouse floors is a room's (as the steps below tell them): a few cells of a
            # floor found in a corridor-and-halls region do not keep its corridor from being looked for
            size, on_floor = on_floors.counts(segments)
            segments, first_beyond = join_corridor_pieces(
                segments, [ln for g in used for ln in g.lines], 2 * on_floor <= size, resolution_m=resolution_m,
                occupied=occupied, beyond_min_area_m2=corridor_beyond_min_m2,
            )
            if first_beyond <= int(segments.max()):
                beyond = segments >= first_beyond
        if rejoin_room_pieces and room_stage:  # pieces of one room that were pieces of the corridor's region when the
            # room stage joined them: with the corridor parted from the rooms, its union with a room is a T, no longer
            # their L
            segments = join_furnished_pieces(
                segments, clutter, floor_px if beyond is None else floor_px | beyond, resolution_m=resolution_m
            )
        if room_stage and side_by_side.any():  # a cut beside a line across open floor (no doors side by side)
            size, on_floor = on_floors.counts(segments)
            segments = join_across_open_lines(
                segments, side_by_side, joinable=2 * on_floor <= size,
                min_border_px=round(_PASSAGE_MIN_BORDER_M / resolution_m),
                reach_px=max(1, round(door_max_depth_m / resolution_m)),
            )
        # furniture against a wall stands on its room's floor (never a warehouse floor's or a road's)
        if against_walls_job is not None:  # (on a hall every region is on a warehouse floor: nothing grows)
            off_floors = (segments > 0) & ~floor_px
            if off_floors.any():  # else nothing grows either: as it is
                against_walls = against_walls_job.result() & (segments == 0)
                grown = fill_from_neighbours(  # np.where's new image: filled in place
                    np.where(off_floors, segments, 0), against_walls, max_iterations=60, overwrite=True
                )
                # in place, as the streaks below: every step since the segment image returned a new array or the one
                # it was given, read nowhere else
                np.copyto(segments, grown, where=against_walls)
        # the streaks the cleaning took out are free space: they take the region they grow from (in place: every step
        # since the segment image returned a new array or the one it was given, read nowhere else)
        segments = fill_from_neighbours(
            segments, streaks, max_iterations=max(1, round(streak_reach_m / resolution_m)), overwrite=True
        )
        # on a rack hall every region still mostly on the floors with its streaks: the fans, the insides of furniture,
        # the passages and the unseen openings leave it as it is (ids 1..N still): not run, nor their counts
        settled = False
        if not room_stage:
            size, on_floor = on_floors.counts(segments)
            settled = bool(np.all(on_floor[1:] > 0.5 * size[1:]))
        door_rooms = None
        if fan_max_neck_m > 0 and settled:
            door_rooms = np.zeros(occ.shape, dtype=bool)  # no room parted
        elif fan_max_neck_m > 0:  # a room seen only through its door (rays or floor), not the corridor's floor
            size, on_floor = on_floors.counts(segments)
            floors = on_floor > 0.5 * size
            last_id = int(segments.max())
            segments = split_fans(
                segments, occupied, floors,
                resolution_m=resolution_m, max_neck_m=fan_max_neck_m, thin=rays | streaks,
                wide_neck_m=door_max_width_m, lobe_max_area_m2=room_min_area_m2,
            )
            door_rooms = segments > last_id  # the rooms it parted, under ids above the others
        if inside_furniture_max_m2 > 0 and not settled:  # the inside of a cupboard or a hollow pillar: its room's floor
            size, on_floor = on_floors.counts(segments)
            segments = inside_furniture(
                segments, on_floor > 0.5 * size, resolution_m=resolution_m, max_area_m2=inside_furniture_max_m2
            )
        if passage_max_m2 > 0 and not settled:  # a strip between two cuts is no room: it joins the piece it borders
            size, on_floor = on_floors.counts(segments)
            segments = merge_passages(
                segments, max_area_px=round(passage_max_m2 / resolution_m**2),
                max_width_px=_PASSAGE_MAX_WIDTH_M / resolution_m,
                min_border_px=round(_PASSAGE_MIN_BORDER_M / resolution_m), fixed=on_floor > 0.5 * size,
            )
        if unseen_opening_m > 0 and not settled:  # a cut from unknown space to unknown space parts nothing seen
            size, on_floor = on_floors.counts(segments)
            segments = join_unseen_openings(
                segments, obstacle, occupied, resolution_m=resolution_m, fixed=on_floor > 0.5 * size,
                max_width_m=cut_max_width_m, unseen_m=unseen_opening_m,
            )
            if passage_max_m2 > 0:  # a piece of corridor between two cuts on the grey fringe of unseen walls
                size, on_floor = on_floors.counts(segments)
                segments = join_unseen_passages(
                    segments, obstacle, occupied, resolution_m=resolution_m, fixed=on_floor > 0.5 * size,
                    max_area_m2=passage_max_m2, min_border_m=_PASSAGE_MIN_BORDER_M, seen_min_m=_PASSAGE_MIN_BORDER_M,
                )
        # racks, aisles, cross aisles and junctions: a region each, labelled as the racks say
        floor_space = free | streaks
        segments, places = place_segments(
            segments, racks, floor_space, min_area_px=round(room_min_area_m2 / resolution_m**2),
            n_known=0 if known_places is None else known_places.cell_labels.size - 1,
        )  # streaks the cleaning took out of a rack (a flue seen through an empty bay) are in it too
        on_places = places > 0
        if prior is not None:
            if prior.regions.shape != occ.shape or prior.unchanged.shape != occ.shape:
                raise DecompositionError(f"a prior of shape {prior.regions.shape} on a grid of {occ.shape}")
            # rack places (racks, aisles, cross aisles) are found anew every time: a rack is often seen whole only
            # later
            segments = keep_regions(
                segments, RegionPrior(np.where(on_places, 0, prior.regions), prior.unchanged & ~on_places),
                max_changed_share=settled_max_changed_share,
                min_area_px=max(1, round(min_region_area_m2 / resolution_m**2)),
                join_min_border_px=round(door_max_width_m / resolution_m),
                door_rooms=door_rooms,
                sliver_max_px=round(room_min_area_m2 / resolution_m**2),
                first_seen_min_px=round(first_seen_piece_min_m2 / resolution_m**2),
                first_seen_max_px=round(first_seen_room_max_m2 / resolution_m**2),
                first_seen_min_border_px=round(door_max_width_m / resolution_m),
                apart=on_places,
            )
            if fan_max_neck_m > 0:  # a settled region holds a room seen through its door as it held it before the
                # room's walls were seen: the rooms behind doors are parted from the regions as kept, too
                size, on_floor = label_counts(segments, int(segments.max()) + 1, floor_px | on_places)
                segments = split_fans(
                    segments, occupied, on_floor > 0.5 * size,
                    resolution_m=resolution_m, max_neck_m=fan_max_neck_m, thin=rays | streaks,
                    wide_neck_m=door_max_width_m, lobe_max_area_m2=room_min_area_m2,
                )
        # pieces of one fan of rays that touch nothing, each a region too small to be a room, are one room; a room
        # seen alone through the gaps of its walls (touching no region) takes the dots of its rays round it
        fan_gap_px = max(1, round(_FAN_GAP_M / resolution_m))
        segments = join_and_fill_loose(
            segments, free, occupied, max_area_px=round(room_min_area_m2 / resolution_m**2), gap_px=fan_gap_px,
            reach_px=fan_gap_px, min_area_px=round(min_region_area_m2 / resolution_m**2),
        )
        # a dot of a ray between two cells of one region (between two rays of its fan, in a notch of its outline)
        segments = fill_between(segments, free, occupied, reach_px=fan_gap_px, floor=floor_space)
        doorways = door | cuts
        if enclosed_dots_m > 0:  # the dots beyond a fan's end that walls and floor close in: inside the room's walls
            dot_reach_px = max(1, round(_DOT_REACH_M / resolution_m))
            enclosed_px = max(1, round(enclosed_dots_m / resolution_m))
            speck_px = max(1, round(min_region_area_m2 / resolution_m**2))
            segments = fill_enclosed(
                segments, free, occupied, doorways, reach_px=dot_reach_px, enclosed_px=enclosed_px,
                min_area_px=speck_px, floor=floor_space,
            )  # in line with a region's floor; then beside it, the streaks beyond the streak fill too
            segments = fill_near(
                segments, free | streaks, occupied, doorways, reach_px=dot_reach_px, enclosed_px=enclosed_px,
                min_area_px=speck_px,
            )
        if free_standing_ends and room_stage:  # a wide border ending on an obstacle that stands free: no doorway
            size, on_floor = label_counts(segments, int(segments.max()) + 1, floor_px | on_places)
            segments = join_free_standing_ends(
                segments, free, occupied, wall, resolution_m=resolution_m, min_border_m=door_max_width_m,
                joinable=(on_floor <= 0.5 * size) & (size >= room_min_area_m2 / resolution_m**2),
                hit_parts=occupied_parts,
            )
        # dots of rays a region's first labels took into another room, far from the region's body: that room's
        segments = give_far_pieces(
            segments, occupied, on_places, far_px=round(_FAR_PIECE_M / resolution_m),
            reach_px=round(_FAR_PIECE_REACH_M / resolution_m),
        )
        if room_stage:  # a region of rays whose border with a larger one the laser saw through is that one's
            size, on_floor = label_counts(segments, int(segments.max()) + 1, floor_px | on_places)
            segments = join_ray_pieces(
                segments, occupied, rays, on_floor <= 0.5 * size,
                seen_px=_SEEN_WALL_M / resolution_m, min_border_px=max(1, round(_RAY_BORDER_MIN_M / resolution_m)),
            )
        grown_labels = beside.submit(_grown_face_labels, segments, face_labels, sub.face_image)  # beside the pairs
        closure = beside.submit(border_closure, segments, doorways)  # for the region graph, beside the records
        pairs = _pairs(segments, sub)
        racked = floor_px | banks.storage | on_places  # the only floor a storage region may stand on
        regions, labels = _region_records(segments, pairs, face_labels, grown_labels.result(), racked, resolution_m,
                                          origin_xy_m)
        # pockets of floor between pallets are no rooms; open floor off a rack or warehouse floor is no storage
        structured_segments = set(
            np.flatnonzero(MaskCounts(on_places | floor_px).inside(segments)).tolist()
        )
        rooms = [k for k, r in regions.items() if r.label is PlaceLabel.ROOM and k not in structured_segments]
        open_areas = {k for k, r in regions.items() if r.label is PlaceLabel.OPEN_AREA}
        objects = (
            floor_objects(occupied, known, resolution_m=resolution_m, labelled=occupied_parts)
            if rooms and open_areas
            else np.zeros_like(free)
        )
        merges = pocket_merges(
            segments, rooms, open_areas, objects, free, max_area_px=round(_POCKET_MAX_M2 / resolution_m**2)
        )
        if merges:
            lut = np.arange(int(segments.max()) + 1, dtype=np.int32)
            lut[list(merges)] = list(merges.values())
            segments = lookup(lut[lut], segments)
            grown_labels = beside.submit(_grown_face_labels, segments, face_labels, sub.face_image)
            closure = beside.submit(border_closure, segments, doorways)
            pairs = _pairs(segments, sub)
            regions, labels = _region_records(segments, pairs, face_labels, grown_labels.result(), racked,
                                              resolution_m, origin_xy_m)
        # a region under a room's least area is no room, whatever its faces say (open floor)
        regions = {k: r._replace(label=PlaceLabel.OPEN_AREA)
                   if r.label is PlaceLabel.ROOM and r.area_m2 < room_min_area_m2 else r for k, r in regions.items()}
        room_ids = [k for k, r in regions.items() if r.label is PlaceLabel.ROOM]
        in_places = MaskCounts(on_places).inside(segments) if room_ids else np.zeros(1, dtype=np.int64)
        on_rack_places = [k for k in room_ids if in_places[k] > 0]  # (every pixel counted only for these)
        if on_rack_places:  # a room mostly on rack places is no room: it takes their label
            size = label_counts(segments, in_places.size)[0]
            for k in on_rack_places:
                if in_places[k] > 0.5 * size[k]:
                    held = places[segments == k]
                    label = PlaceLabel(int(np.bincount(racks.cell_labels[held[held > 0]]).argmax()))
                    regions[k] = regions[k]._replace(label=label)
        if known_places is not None:  # in a hall another stage knows the racks of, floor touching a rack place
            # is no room
            hall = cv2.dilate((racks.cells > 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
            in_hall = set(np.unique(segments[hall & (places == 0)]).tolist())
            regions = {k: r._replace(label=PlaceLabel.OPEN_AREA) if r.label is PlaceLabel.ROOM and k in in_hall else r
                       for k, r in regions.items()}
        if label_overrides:  # a region of a renamed category is a place of that name (a rack place mixes categories)
            regions = {
                k: r._replace(label=label_overrides[r.category]) if r.category in label_overrides else r
                for k, r in regions.items()
            }
        face_region = _final_face_regions(pairs, sub.n_faces)
        topology_job = beside.submit(  # (none of these names is bound again below)
            lambda: region_topology(
                sub, cog, face_region, regions, segments=segments, doorways=doorways,
                min_border_px=max(1, round(_MIN_PASSAGE_M / resolution_m)), closure=closure.result(),
            )
        )
        region_label = np.zeros(int(segments.max()) + 1, dtype=np.uint8)
        for k, r in regions.items():
            region_label[k] = r.label.value
        own = lookup(region_label, segments)  # by runs: a faster gather than indexing, the same values
        loose = (labels == PlaceLabel.ROOM.value) | (labels == PlaceLabel.STORAGE.value) & ~floor_px & ~banks.storage
        loose |= (own == PlaceLabel.OPEN_AREA.value) & ~floor_px  # passages between pallets on open floor
        # written into the record step's label image (its own uint8 array, read nowhere else): no fresh image per step
        np.copyto(labels, own, where=loose & (own > 0))
        # a rack place's label, unless a person renamed the category of the face there
        kept_place = on_places
        if label_overrides:
            kept_place = kept_place & ~np.isin(face_labels.category[sub.face_image], list(label_overrides))
        if kept_place.any():
            np.copyto(labels, lookup(racks.cell_labels.astype(np.uint8), places), where=kept_place)  # below 256
        np.multiply(labels, floor_space, out=labels)  # 0 off the floor space
        return Decomposition(
            labels=labels,
            segments=segments,
            regions=regions,
            topology=topology_job.result(),
            line_groups=tuple(groups),
            subdivision=sub,
            cogency=cog,
            face_labels=face_labels,
            texture_regions=texture,
            resolution=resolution,
            resolution_m=resolution_m,
            origin_xy_m=origin_xy_m,
            rack_rows_px=racks.rows_px,
        )


def _on_floors_only(segments: npt.NDArray[np.int32], floor: npt.NDArray[np.bool_]) -> bool:
    """Whether every segment pixel lies on ``floor`` (warehouse floors and rack places: a rack hall).

    The room stage and the corridor steps leave such segments as they are (each passes over a segment mostly on
    the floors, and the segment image's ids are 1..N already), and so do the fans, the insides of furniture, the
    passages and the unseen openings while every segment stays mostly on them: ``decompose`` then runs none of them.
    """
    return not np.any((segments > 0) & ~floor)


class _Pairs(NamedTuple):
    """Pixel counts of every (face, segment) pair present (face 0 = line pixels), sorted by (face, segment)."""

    face: npt.NDArray[np.int64]
    segment: npt.NDArray[np.int64]
    pixels: npt.NDArray[np.float64]


def _pairs(segments: npt.NDArray[np.int32], sub: Subdivision) -> _Pairs:
    """(face, segment) pixel counts from the runs of equal (face, segment) pairs in raster order.

    A face lies in few segments and a segment's faces are large: far fewer runs than pixels. The
    runs' pairs (segment > 0) are sorted once and their lengths summed (whole numbers, exact).
    """
    f = np.ascontiguousarray(sub.face_image).ravel()
    s = np.ascontiguousarray(segments).ravel()
    start = np.empty(f.size, dtype=bool)
    start[0] = True
    np.not_equal(f[1:], f[:-1], out=start[1:])
    start[1:] |= s[1:] != s[:-1]
    first = np.flatnonzero(start)
    length = np.diff(np.append(first, f.size))
    on = s[first] > 0
    first, length = first[on], length[on]
    n_seg = np.int64(int(s.max()) + 1)
    keys, which = unique_inverse(f[first].astype(np.int64) * n_seg + s[first])
    pixels = np.bincount(which, weights=length, minlength=keys.size).astype(np.float64)
    return _Pairs(keys // n_seg, keys % n_seg, pixels)


def _final_face_regions(pairs: _Pairs, n_faces: int) -> npt.NDArray[np.int64]:
    """Region of each face after segment cleaning (majority of its pixels; ties to the lower id)."""
    out = np.zeros(n_faces + 1, dtype=np.int64)
    ok = pairs.face > 0
    face, seg, pixels = pairs.face[ok], pairs.segment[ok], pairs.pixels[ok]
    order = np.lexsort((-pixels, face))
    first = np.r_[True, face[order][1:] != face[order][:-1]] if face.size else np.zeros(0, dtype=bool)
    out[face[order][first]] = seg[order][first]
    return out


def _grown_face_labels(
    segments: npt.NDArray[np.int32], face_labels: FaceLabels, face_image: npt.NDArray[np.int32]
) -> npt.NDArray[np.uint8]:
    """Each segment pixel's face label; line pixels take a neighbour's (0 where none reaches)."""
    inside = segments > 0
    # gathered and filled as bytes (labels are below 256), in the image gathered
    return fill_bytes_from_neighbours(
        np.where(inside, np.take(face_labels.label.astype(np.uint8), face_image), np.uint8(0)), inside, overwrite=True
    )


def _region_records(
    segments: npt.NDArray[np.int32],
    pairs: _Pairs,
    face_labels: FaceLabels,
    grown_labels: npt.NDArray[np.uint8],
    racked: npt.NDArray[np.bool_],
    resolution_m: float,
    origin_xy_m: tuple[float, float],
) -> tuple[dict[int, RegionInfo], npt.NDArray[np.uint8]]:
    """Region records (label: its faces' majority) and the label image (each face's own label,
    :func:`_grown_face_labels`; its region's where none reaches).

    Open floor is never storage: a region mostly off ``racked`` (racks, rack places, warehouse
    floors, shelf banks) takes the majority of its other faces' labels, open area when all its
    faces are bay-shaped (a few rectangles between furniture in a home look like pallet cells).
    """
    n_seg = int(segments.max()) + 1
    n_lab = len(PlaceLabel)
    lab_votes = np.bincount(
        pairs.segment * n_lab + face_labels.label[pairs.face], weights=pairs.pixels, minlength=n_seg * n_lab
    ).reshape(n_seg, n_lab)
    lab_votes[:, 0] = 0
    storage = PlaceLabel.STORAGE.value
    off_racks = _share_in(segments, racked, n_seg) < 0.5
    only_storage = off_racks & (lab_votes[:, storage] > 0) & (lab_votes.sum(axis=1) == lab_votes[:, storage])
    lab_votes[off_racks, storage] = 0
    seg_label = np.argmax(lab_votes, axis=1)
    seg_label[lab_votes.sum(axis=1) == 0] = PlaceLabel.UNIDENTIFIED.value
    seg_label[only_storage] = PlaceLabel.OPEN_AREA.value
    n_cat = int(max(face_labels.category.max(), 0)) + 2
    cat_votes = np.bincount(
        pairs.segment * n_cat + face_labels.category[pairs.face] + 1, weights=pairs.pixels, minlength=n_seg * n_cat
    ).reshape(n_seg, n_cat)
    seg_cat = np.argmax(cat_votes, axis=1) - 1
    area = np.bincount(pairs.segment, weights=pairs.pixels, minlength=n_seg)
    _, sx, sy = label_sums(segments, n_seg)
    regions: dict[int, RegionInfo] = {}
    for sid in np.flatnonzero(area[1:] > 0) + 1:
        cx = origin_xy_m[0] + (sx[sid] / area[sid] + 0.5) * resolution_m
        cy = origin_xy_m[1] + (sy[sid] / area[sid] + 0.5) * resolution_m
        regions[int(sid)] = RegionInfo(
            int(sid), PlaceLabel(int(seg_label[sid])), int(seg_cat[sid]), area[sid] * resolution_m**2, (cx, cy)
        )
    labels = grown_labels  # its holes filled in place
    hole = (segments > 0) & (labels == 0)
    labels[hole] = seg_label[segments[hole]]  # label values, below 256
    return regions, labels


def _share_in(segments: npt.NDArray[np.int32], mask: npt.NDArray[np.bool_], n_seg: int) -> npt.NDArray[np.float64]:
    """(n_seg,) share of each segment's pixels inside ``mask``."""
    if not mask.any():
        return np.zeros(n_seg)
    area, inside = label_counts(segments, n_seg, mask)
    share: npt.NDArray[np.float64] = inside / np.maximum(area, 1)
    return share
