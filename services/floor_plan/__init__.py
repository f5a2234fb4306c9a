"""Floor plan: a parametric world of rectangular units, doors and unit types by knowledge-supervised MCMC.

Seed 003, chapter 3: an occupancy grid is explained by units (rectangles with four walls), doors between
adjacent units and a type per unit (room, corridor, hall, other), found by data-driven Metropolis-Hastings
under a Markov-logic context prior.
"""

from services.floor_plan.chain import SEED_SCHEDULE, Chain, ChainResult, ChainSettings, Phase, run_chain
from services.floor_plan.clutter import Clutter, explain_clutter, explain_exterior
from services.floor_plan.context import ContextPrior, ContextSettings, UnitEvidence, type_marginals
from services.floor_plan.errors import FloorPlanError
from services.floor_plan.frame import Frame, carry, dominant_angle, make_frame
from services.floor_plan.kernels import Kernel, KernelSettings, Move, Proposer
from services.floor_plan.likelihood import (
    SEED_SENSOR_MODEL,
    Canvas,
    CellClass,
    cell_prediction_rate,
    classify_map,
    log_sensor_table,
    render,
)
from services.floor_plan.pipeline import (
    Door,
    FloorPlan,
    FloorPlanSettings,
    Unit,
    describe,
    floor_plan,
    room_labels,
    unit_labels,
)
from services.floor_plan.rooms import FurnitureSettings, Room, RoomSettings, group_rooms, room_keys
from services.floor_plan.slanted import split_at_slanted_walls
from services.floor_plan.walls import Segment, Slant, Walls, fit_walls
from services.floor_plan.world import Rect, Side, UnitType, World

__all__ = [
    "SEED_SCHEDULE",
    "SEED_SENSOR_MODEL",
    "Canvas",
    "CellClass",
    "Chain",
    "ChainResult",
    "ChainSettings",
    "Clutter",
    "ContextPrior",
    "ContextSettings",
    "Door",
    "FloorPlan",
    "FloorPlanError",
    "FloorPlanSettings",
    "Frame",
    "FurnitureSettings",
    "Kernel",
    "KernelSettings",
    "Move",
    "Phase",
    "Proposer",
    "Rect",
    "Room",
    "RoomSettings",
    "Segment",
    "Side",
    "Slant",
    "Unit",
    "UnitEvidence",
    "UnitType",
    "Walls",
    "World",
    "carry",
    "cell_prediction_rate",
    "classify_map",
    "describe",
    "dominant_angle",
    "explain_clutter",
    "explain_exterior",
    "fit_walls",
    "floor_plan",
    "group_rooms",
    "log_sensor_table",
    "make_frame",
    "render",
    "room_keys",
    "room_labels",
    "run_chain",
    "split_at_slanted_walls",
    "type_marginals",
    "unit_labels",
]
