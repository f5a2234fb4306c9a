"""The floor-plan worker: occupancy revisions in, units, doors and their types out, warm-started.

It follows the map events (``/aisle/map_events``) and looks at the store every ``safety_poll_period_s`` (and once
on start). When the source layer has a revision it has not explained and ``min_period_s`` has passed, it fits a
floor plan, starting from the last world it found (moved to the new grid's origin: a growing map does not
restart the chain) with ``warm_iterations``, and commits ONE revision: the ``floor_plan`` layer (C_W), ``unit``
and ``door`` features and the unit graph. A grid it cannot use is counted as ``floor_plan_errors``. On start the
source revision, the last world and the robot positions heard so far (kept in the layer's meta) are read back
from the stored layer, so a grid is not explained twice and the first plan after a restart is warm-started too.
Where robots have been (the tracks of the ``robot`` features the occupancy stage stores) seeds unit candidates.
"""

from __future__ import annotations

import logging
import math
import threading
import time

import numpy as np

from services.floor_plan.chain import ChainSettings
from services.floor_plan.context import ContextSettings
from services.floor_plan.errors import FloorPlanError
from services.floor_plan.frame import Frame, carry, make_frame
from services.floor_plan.pipeline import FloorPlanSettings, floor_plan
from services.floor_plan.records import plan_features, plan_layer, plan_topology, world_from_meta, world_meta
from services.floor_plan.world import World
from shared.robots import Robot, RobotError
from shared.settings import FloorPlanStageSettings
from shared.store import GridLayer, RevisionWrite, StoredLayer, StoreUnavailableError
from shared.vocabulary import FeatureKind
from shared.worker import StageContext, checked

log = logging.getLogger(__name__)

_POSITION_STEP_M = 0.25  # robot positions are kept on a grid this fine, metres
_MAX_POSITIONS = 20000  # at most this many (5 km of track at one a step)
_WAKE_S = 0.25  # longest wait for a map event before the stop flag is looked at again, seconds
_RETRY_S = 2.0  # how soon the store is looked at again after it was unavailable, seconds


class FloorPlanStage:
    """Stage ``floor_plan``, built from its settings section; see the module docstring."""

    def __init__(self, context: StageContext, settings: FloorPlanStageSettings) -> None:
        self.context = context
        self.settings = settings = checked(settings, FloorPlanError)
        self.events = context.map_events()
        self._done: int | None = None  # source revision explained last
        self._world: World | None = None
        self._frame: Frame | None = None  # the frame of the last world
        self._positions: set[tuple[float, float]] = set()  # where robots have been (the robot-position detector)
        self._last_attempt = -float("inf")
        self._started = False

    def run(self, stop: threading.Event) -> None:
        look_at = 0.0
        while not stop.is_set():
            if time.monotonic() >= look_at:
                try:
                    pending = self._look()
                    look_at = time.monotonic() + self.settings.safety_poll_period_s
                    if pending:
                        look_at = min(look_at, self._last_attempt + self.settings.min_period_s)
                except StoreUnavailableError as err:
                    self.context.count("store_unavailable")
                    log.warning("store unavailable, will retry: %s", err)
                    look_at = time.monotonic() + _RETRY_S
            if self._announced(timeout_s=min(_WAKE_S, max(0.0, look_at - time.monotonic()))):
                look_at = 0.0

    def _announced(self, *, timeout_s: float) -> bool:
        announced = False
        item = self.events.receive(timeout_s)
        while item is not None:
            event = item.message
            announced |= (str(event.map_name) == self.context.map.name
                          and self.settings.source_layer in event.layers_updated)
            item = self.events.receive()
        return announced

    def _look(self) -> bool:
        """Explain the newest source layer if it is new; whether one waits for ``min_period_s``."""
        store, map_id = self.context.store, self.context.map.id
        if not self._started:
            mine = store.layer(map_id, self.settings.layer)
            if mine is not None:
                source = mine.layer.meta.get("source_revision")
                self._done = source if isinstance(source, int) else None
                self._world = world_from_meta(mine.layer.meta)
                self._remember(mine.layer.meta.get("robot_positions"))
                angle = mine.layer.meta.get("angle_rad", 0.0)
                self._frame = make_frame(mine.layer.data.shape, angle_rad=float(angle) if isinstance(
                    angle, int | float) else 0.0, origin_xy_m=(mine.layer.origin_x_m, mine.layer.origin_y_m),
                    resolution_m=mine.layer.resolution_m)
            self._started = True
        stored = store.layer(map_id, self.settings.source_layer)
        if stored is None or stored.revision_id == self._done:
            return False
        if time.monotonic() - self._last_attempt < self.settings.min_period_s:
            return True
        self._plan(stored)
        return False

    def _start_world(self, layer: GridLayer) -> tuple[World | None, float | None]:
        """The last world moved into the frame of ``layer`` (same angle: a growing map keeps its axes)."""
        if self._world is None or self._frame is None:
            return None, None
        frame = make_frame(layer.data.shape, angle_rad=self._frame.angle_rad,
                           origin_xy_m=(layer.origin_x_m, layer.origin_y_m), resolution_m=layer.resolution_m)
        return carry(self._world, self._frame, frame), frame.angle_rad

    def _plan(self, stored: StoredLayer) -> None:
        s, layer = self.settings, stored.layer
        self._last_attempt = time.monotonic()
        self._done = stored.revision_id
        start, angle = self._start_world(layer)
        self._hear_robots()
        settings = FloorPlanSettings(
            wall_m=s.wall_m,
            chain=ChainSettings(iterations=s.warm_iterations if start else s.iterations, max_seconds=s.max_seconds,
                                restarts=s.restarts),
            context=ContextSettings(hall_area_m2=s.hall_area_m2, corridor_ratio=s.corridor_ratio,
                                    type_rule_weight=s.type_rule_weight,
                                    same_length_rule_weight=s.same_length_rule_weight,
                                    same_length_sigma_m=s.same_length_sigma_m),
            clutter_max_m2=s.clutter_max_m2, clutter_log_cost=s.clutter_log_cost, wall_shift_m=s.wall_shift_m,
        )
        try:
            plan = floor_plan(layer.data, resolution_m=layer.resolution_m,
                              origin_xy_m=(layer.origin_x_m, layer.origin_y_m), settings=settings, start=start,
                              angle_rad=angle, trajectory_xy_m=np.array(sorted(self._positions)).reshape(-1, 2))
        except FloorPlanError as err:
            self.context.count("floor_plan_errors")
            log.warning("%s revision %d (%d x %d cells) not explained: %s", s.source_layer, stored.revision_id,
                        layer.data.shape[1], layer.data.shape[0], err)
            return
        source = {"source_layer": s.source_layer, "source_revision": stored.revision_id}
        meta = {**source, "world": world_meta(plan.world), "angle_rad": plan.frame.angle_rad,
                "robot_positions": [list(p) for p in sorted(self._positions)]}
        write = RevisionWrite(self.context.name, layers=[plan_layer(plan, name=s.layer, meta=meta)],
                              features=plan_features(plan), topology=plan_topology(plan),
                              summary={**source, "units": len(plan.units), "rooms": len(plan.rooms),
                                       "doors": len(plan.doors),
                                       "k": round(plan.k, 4), "iterations": plan.iterations,
                                       "warm_start": start is not None, "seconds": round(plan.seconds, 3)})
        if self.context.commit(write) is None:
            self._done = None  # store down: counted by commit; try this grid again
            return
        self._world, self._frame = plan.world, plan.frame
        self.context.count("floor_plans")
        log.info("%s revision %d: %d units, %d doors, K(W,M) %.3f, %d iterations in %.2f s", s.source_layer,
                 stored.revision_id, len(plan.units), len(plan.doors), plan.k, plan.iterations, plan.seconds)


    def _hear_robots(self) -> None:
        """Add the tracks of the stored ``robot`` features (each robot's last minute) to the positions kept."""
        for stored in self.context.store.features(self.context.map.id, kinds=[FeatureKind.ROBOT]):
            try:
                robot = Robot.from_feature(stored.feature)
            except RobotError as err:
                self.context.count("bad_robot_features")
                log.warning("robot feature not used: %s", err)
                continue
            self._remember([(p.x_m, p.y_m) for p in (*robot.track, robot.pose)])

    def _remember(self, points: object) -> None:
        """Keep ``points`` ([x, y] metres; anything else is ignored) on the position grid, up to the bound."""
        if not isinstance(points, list | tuple):
            return
        step = _POSITION_STEP_M
        for point in points:
            if len(self._positions) >= _MAX_POSITIONS:
                return
            if (isinstance(point, list | tuple) and len(point) == 2
                    and all(isinstance(v, int | float) and math.isfinite(v) for v in point)):
                self._positions.add((round(point[0] / step) * step, round(point[1] / step) * step))


def floor_plan_stage(context: StageContext) -> FloorPlanStage:
    """The stage built from its settings section, ``context.settings.floor_plan``."""
    return FloorPlanStage(context, context.settings.floor_plan)
