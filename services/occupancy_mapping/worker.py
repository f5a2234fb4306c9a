"""The occupancy-mapping worker: scans and poses from the bus in, the occupancy layer and the robots out.

It integrates scans from every robot it listens to, stores the grid as a revision every
``store_period_s`` and publishes it as nav_msgs/OccupancyGrid on ``/aisle/map`` every
``publish_period_s``. Each stored revision also holds a ``robot`` feature per robot heard: where its lidar
was at its newest integrated scan and its track over the last minute. On start it resumes from the stored
layer, so a restart loses nothing that was committed.
"""

from __future__ import annotations

import logging
import threading
import time

from services.occupancy_mapping.errors import OccupancyMappingError
from services.occupancy_mapping.grid import OccupancyGrid
from services.occupancy_mapping.mapper import AUTO_FRAME, ScanMapper
from services.occupancy_mapping.scanmatch import ScanMatcher
from shared import messages
from shared.bus import WORKER_NAMESPACE
from shared.grids import occupancy_grid_message
from shared.settings import OccupancySettings
from shared.store import RevisionWrite, StoreUnavailableError
from shared.vocabulary import FeatureKind
from shared.worker import IDLE_WAIT_S, StageContext, drain

log = logging.getLogger(__name__)

MAP_TOPIC = "map"
_BATCH = 50


class OccupancyStage:
    """Stage ``occupancy_mapping``; see the module docstring."""

    def __init__(self, context: StageContext, settings: OccupancySettings) -> None:
        self.context = context
        self.settings = settings
        self.scans = context.subscribe(settings.scan_topic, messages.LASER_SCAN, maxsize=500)
        self.odometry = context.subscribe(settings.odom_topic, messages.ODOMETRY, maxsize=2000)
        self.tf, self.tf_static = context.subscribe_transforms()
        pose_topic = settings.pose_topic
        self.poses = context.subscribe(pose_topic, messages.POSE_STAMPED, maxsize=2000) if pose_topic else None
        self.matcher = (
            ScanMatcher(window_m=self.settings.scan_matching_window_m,
                        window_rad=self.settings.scan_matching_window_rad, max_range_m=self.settings.max_range_m)
            if self.settings.scan_matching
            else None
        )
        self.mapper = ScanMapper(self._resume(), fixed_frame=AUTO_FRAME, max_range_m=self.settings.max_range_m,
                                 corrector=self.matcher)
        self._publisher = context.bus.publisher(MAP_TOPIC, messages.OCCUPANCY_GRID, namespace=WORKER_NAMESPACE)
        self._integrated_since_store = 0
        self._integrated_since_publish = 0

    def _resume(self) -> OccupancyGrid:
        resolution = self.settings.resolution_m
        try:
            stored = self.context.store.layer(self.context.map.id, self.settings.layer)
        except StoreUnavailableError as err:
            log.warning("cannot read the stored occupancy layer, starting empty: %s", err)
            stored = None
        if stored is None or abs(stored.layer.resolution_m - resolution) > 1e-9:
            return OccupancyGrid(resolution_m=resolution)
        layer = stored.layer
        log.info("resuming occupancy layer of revision %d (%d x %d cells)", stored.revision_id, *layer.data.shape)
        return OccupancyGrid.from_occupancy(layer.data, resolution_m=layer.resolution_m,
                                            origin_x_m=layer.origin_x_m, origin_y_m=layer.origin_y_m)

    def run(self, stop: threading.Event) -> None:
        last_store = last_publish = time.monotonic()
        try:
            while not stop.is_set():
                self._take_poses()
                self._take_scans(timeout_s=IDLE_WAIT_S)
                self._take_poses()
                integrated = self.mapper.drain()
                self._integrated_since_store += integrated
                self._integrated_since_publish += integrated
                self._sync_counts()
                now = time.monotonic()
                if now - last_store >= self.settings.store_period_s:
                    last_store = now
                    self._store()
                if now - last_publish >= self.settings.publish_period_s:
                    last_publish = now
                    self._publish()
        finally:
            self._take_poses()
            self._take_scans(timeout_s=0.0)
            self._integrated_since_store += self.mapper.drain(final=True)
            self._sync_counts()
            self._store()

    def _take_poses(self) -> None:
        for subscription, static in ((self.tf_static, True), (self.tf, False)):
            for item in drain(subscription):
                self.mapper.add_tf(item.namespace, item.message, static=static)
        for item in drain(self.odometry):
            self.mapper.add_odometry(item.namespace, item.message)
        for item in drain(self.poses):
            self.mapper.add_map_pose(item.namespace, item.message, base_frame=self.settings.base_frame)

    def _take_scans(self, *, timeout_s: float) -> None:
        item = self.scans.receive(timeout_s)
        taken = 0
        while item is not None and taken < _BATCH:
            try:
                self.mapper.add_scan(item.namespace, item.message, fallback_stamp_ns=item.received_ns)
            except OccupancyMappingError as err:
                self.context.count("malformed_scans")
                log.warning("scan from %r skipped: %s", item.namespace or "/", err)
            taken += 1
            item = self.scans.receive() if taken < _BATCH else None

    def _sync_counts(self) -> None:
        counts = self.mapper.counts + self.matcher.counts if self.matcher else self.mapper.counts
        for name, value in counts.items():
            self.context.counters.set(f"{self.context.name}.{name}", value)

    def _store(self) -> None:
        if self._integrated_since_store == 0:
            return
        grid = self.mapper.grid
        layer = grid.to_layer(self.settings.layer)
        robots = [robot.feature() for robot in self.mapper.tracks.robots()]
        write = RevisionWrite(self.context.name, layers=[layer], features={FeatureKind.ROBOT: robots},
                              input_start_ns=self.mapper.first_stamp_ns,
                              input_end_ns=self.mapper.last_stamp_ns,
                              summary={"scans": self._integrated_since_store})
        revision = self.context.commit(write)
        if revision is not None:
            known = int((layer.data >= 0).sum()) * layer.resolution_m**2
            log.info("revision %d: occupancy %d x %d cells, %.0f m² mapped, %d new scans", revision.id,
                     layer.data.shape[1], layer.data.shape[0], known, self._integrated_since_store)
            self._integrated_since_store = 0

    def _publish(self) -> None:
        if self._integrated_since_publish == 0:
            return
        self._integrated_since_publish = 0
        layer = self.mapper.grid.to_layer(self.settings.layer)
        message = occupancy_grid_message(layer, stamp_ns=self.mapper.last_stamp_ns or time.time_ns(),
                                         frame_id=self.settings.map_frame)
        self._publisher.publish(message)


def occupancy_stage(context: StageContext) -> OccupancyStage:
    """The stage built from its settings section, ``context.settings.occupancy``."""
    return OccupancyStage(context, context.settings.occupancy)
