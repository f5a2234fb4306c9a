"""``aisle``: one command for every way Aisle runs."""

from __future__ import annotations

import argparse
import gc
import json
import logging
import math
import sys
import threading
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import ValidationError

from shared.heap import keep_freed_memory
from shared.settings import STAGES, RackProfileSettings, Settings, get_settings

if TYPE_CHECKING:
    from shared.bus import Bus

log = logging.getLogger("aisle")


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text} is not a positive number")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="aisle", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="all stages and the API in one process")
    run.add_argument("--replay", type=Path, metavar="BAG", help="also replay this rosbag2 onto the bus")
    run.add_argument("--rate", type=_positive, default=1.0, help="replay speed factor")
    run.add_argument("--loop", action="store_true", help="replay in a loop")
    run.add_argument("--demo", action="store_true", help="also drive a simulated robot round a demo warehouse")
    run.add_argument("--demo-rate", type=_positive, default=1.0, help="demo speed factor (1 = real time)")
    run.add_argument("--demo-cameras", default="fisheye",
                     help="cameras the demo robot carries, comma-separated (fisheye,rgbd; empty for none)")

    worker = commands.add_parser("worker", help="one stage worker")
    worker.add_argument("stage", choices=STAGES)

    commands.add_parser("serve", help="the API only")
    db = commands.add_parser("db", help="database schema and retention").add_subparsers(
        dest="db_command", required=True, metavar="DB_COMMAND")
    db.add_parser("upgrade", help="bring the schema up to date")
    compact = db.add_parser("compact", help="thin old revisions by the retention settings, then VACUUM (SQLite)")
    compact.add_argument("--dry-run", action="store_true", help="only print what would go")
    compact.add_argument("--map", default=None, help="map name (default: every map)")
    for name, what in (("pin", "keep a revision whatever the retention settings say"), ("unpin", "undo a pin")):
        pin = db.add_parser(name, help=what)
        pin.add_argument("revision", type=int)
        pin.add_argument("--map", default=None, help="map name (default: the configured map_name)")
    commands.add_parser("settings", help="print the effective settings as JSON")

    replay = commands.add_parser("replay", help="publish a rosbag2 file onto the bus with its timing")
    replay.add_argument("bag", type=Path)
    replay.add_argument("--rate", type=_positive, default=1.0)
    replay.add_argument("--loop", action="store_true")
    replay.add_argument("--namespace", default="", help="extra ROS namespace to publish under")

    record = commands.add_parser("record", help="record bus traffic to an MCAP rosbag2")
    record.add_argument("out", type=Path)

    carmen = commands.add_parser("import-carmen", help="convert a CARMEN log (FLASER) to rosbag2")
    carmen.add_argument("log", type=Path)
    carmen.add_argument("out", type=Path)

    build = commands.add_parser("map-build", help="build an occupancy map offline from a rosbag2")
    build.add_argument("bag", type=Path)
    build.add_argument("--out", type=Path, required=True, help="map_server YAML to write (PGM beside it)")
    build.add_argument("--resolution", type=_positive, default=None, help="metres per cell")
    build.add_argument("--scan-topic", default=None)
    build.add_argument("--scan-matching", action="store_true",
                       help="correct odometry drift by matching scans to the map (for logs without corrected poses)")
    _add_sim(commands)

    decompose = commands.add_parser("decompose", help="corridors, junctions, storage and rooms of an occupancy map")
    decompose.add_argument("map", type=Path, help="map_server YAML, or a bare PNG/PGM with --resolution")
    decompose.add_argument("--out", type=Path, required=True, help="folder for labels, segments, layout, topology")
    decompose.add_argument("--resolution", type=_positive, default=None, help="metres per pixel of a bare image")
    decompose.add_argument("--labels", default="", help="category overrides, e.g. 0=corridor,3=storage")

    plan = commands.add_parser("floor-plan", help="units, doors and unit types of an occupancy map (MCMC)")
    plan.add_argument("map", type=Path, help="map_server YAML, or a bare PNG/PGM with --resolution")
    plan.add_argument("--out", type=Path, required=True, help="folder for floor_plan.geojson, units.png, overview.png")
    plan.add_argument("--resolution", type=_positive, default=None, help="metres per pixel of a bare image")
    plan.add_argument("--iterations", type=int, default=20000, help="Metropolis-Hastings iterations")
    plan.add_argument("--max-seconds", type=_positive, default=60.0, help="wall-time bound of the chain")
    plan.add_argument("--seed", type=int, default=0, help="random seed of the chain")
    plan.add_argument("--trajectory", type=Path, default=None,
                      help="CSV of robot positions (x,y in map metres per line): seeds of unit candidates")

    pillars = commands.add_parser("pillars", help="rack uprights from a downward fisheye camera").add_subparsers(
        dest="pillars_command", required=True, metavar="PILLARS_COMMAND")
    detect = pillars.add_parser("detect", help="print bearings to the uprights in one image")
    detect.add_argument("image", type=Path)
    detect.add_argument("--camera-info", type=Path, required=True, help="calibration YAML (equidistant model)")
    pillar_map = pillars.add_parser("map", help="detect and map uprights over a rosbag2")
    pillar_map.add_argument("bag", type=Path)
    pillar_map.add_argument("--out", type=Path, required=True)

    racks = commands.add_parser("racks", help="rack rows and storage bins").add_subparsers(
        dest="racks_command", required=True, metavar="RACKS_COMMAND")
    fit = racks.add_parser("fit", help="fit rack rows and bins to upright landmarks (CSV x,y,sxx,sxy,syy)")
    fit.add_argument("pillars", type=Path)
    fit.add_argument("--out", type=Path, required=True)
    fit.add_argument("--levels", default="", help="the racks' level heights in metres, e.g. 0,1.5,3 (bins per "
                     "level, ids AA-BBB-LL); default: the settings' rack profiles")

    export = commands.add_parser("export", help="write the stored map in a standard format, offline")
    export.add_argument("format", help="export format: geojson, map_server, lif or rmf (as the API's /exports)")
    export.add_argument("--out", type=Path, required=True,
                        help="file to write; map_server writes OUT.yaml and OUT.pgm (OUT may end in .yaml)")
    export.add_argument("--map", default=None, help="map name (default: the configured map_name)")
    export.add_argument("--revision", type=int, default=None, help="revision id to export (default: the newest)")
    export.add_argument("--layer", default=None, help="map_server: the grid layer to export (default: occupancy)")

    keys = commands.add_parser("keys", help="API keys").add_subparsers(
        dest="keys_command", required=True, metavar="KEYS_COMMAND")
    create = keys.add_parser("create", help="create a key; its secret is printed once")
    create.add_argument("--role", choices=["read", "write", "admin"], required=True)
    create.add_argument("--name", required=True, help="who or what the key is for, e.g. wms")
    listing = keys.add_parser("list", help="list keys (never their secrets)")
    listing.add_argument("--all", action="store_true", help="include revoked keys")
    revoke = keys.add_parser("revoke", help="revoke a key")
    revoke.add_argument("key_id")

    for name, what in (("train-classifier", "train the ROI and whole-image SVMs on CNN features"),
                       ("eval-classifier", "per-class ROC AUC and confusion matrices on held-out samples")):
        classifier = commands.add_parser(name, help=what)
        if name == "eval-classifier":
            classifier.add_argument("model", type=Path, nargs="?",
                                    help="model file (default: the stage's labelling.model_path)")
        classifier.add_argument("--data", type=Path, metavar="DIR",
                                help="folder with the YOLO sets pallets/ and forklift_person/ "
                                     "(e.g. ../shared/data/images); without it: simulator renders only")
        classifier.add_argument("--sim-views", type=int, default=400,
                                help="simulator views to train on / evaluate on (0: none)")
        classifier.add_argument("--seed", type=int, default=0, help="seed of the train/test split by source photo")
        classifier.add_argument("--feature-cache", type=Path, metavar="FILE",
                                help="keep CNN features in this .npz between runs")
        if name == "train-classifier":
            classifier.add_argument("--out", type=Path,
                                    help="model file to write (default: the stage's labelling.model_path)")
            classifier.add_argument("--input-size", type=int, default=128, help="CNN input size, pixels")
    return parser


def _add_sim(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    sim = commands.add_parser("sim", help="the warehouse simulator").add_subparsers(
        dest="sim_command", required=True, metavar="SIM_COMMAND")
    world_help = "layout YAML file or preset (demo, hall); omit with --random"
    world = sim.add_parser("world", help="build a world and write its ground truth")
    world.add_argument("layout", nargs="?", help=world_help)
    world.add_argument("--random", action="store_true", help="a random layout drawn with --seed")
    world.add_argument("--seed", type=int, default=0)
    world.add_argument("--out", type=Path, required=True, help="ground-truth folder")
    world.add_argument("--resolution", type=_positive, default=0.05, help="ground-truth grid cell, metres")
    run = sim.add_parser("run", help="simulate robots surveying a world, into a rosbag2 or live onto the bus")
    run.add_argument("layout", nargs="?", help=world_help)
    run.add_argument("--random", action="store_true")
    run.add_argument("--seed", type=int, default=0)
    target = run.add_mutually_exclusive_group(required=True)
    target.add_argument("--out", type=Path, help="MCAP rosbag2 to write (ground truth beside it in OUT.truth/)")
    target.add_argument("--live", action="store_true", help="publish onto the bus in real time")
    run.add_argument("--robots", type=int, default=1)
    run.add_argument("--speed", type=_positive, default=1.2, help="robot speed, m/s")
    run.add_argument("--cameras", default="", help="comma-separated: fisheye,rgbd")
    run.add_argument("--rate", type=_positive, default=1.0, help="live speed factor")


def _configure_logging(level: str) -> None:
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        settings = get_settings()
    except (ValidationError, FileNotFoundError) as err:
        print(f"aisle: bad settings: {err}", file=sys.stderr)
        return 2
    _configure_logging(settings.log_level)
    keep_freed_memory(settings.heap_kept_bytes)
    try:
        return _dispatch(args, settings)
    except (ValueError, OSError, ConnectionError) as err:
        log.error("%s", err)
        return 1


def _dispatch(args: argparse.Namespace, settings: Settings) -> int:
    if args.command in ("pillars", "racks"):  # offline on files: neither bus nor store
        _pillars(args, settings)
        return 0
    if args.command == "decompose":  # offline on files: neither the bus's nor the store's libraries are loaded
        _decompose(args)
        return 0
    from services import runtime

    stop = threading.Event()
    match args.command:
        case "run":
            extra: list[Callable[[Bus, threading.Event], None]] = []
            if args.replay is not None:
                extra.append(partial(_replay_job, bag=args.replay, rate=args.rate, loop=args.loop))
            stages = list(settings.stages)
            if args.demo:
                extra.append(_demo_job(args.demo_cameras, rate=args.demo_rate))
                settings = _demo_settings(settings)
                if "rgbd" in args.demo_cameras.split(","):
                    stages += [] if "object_labelling" in stages else ["object_labelling"]
                    _demo_labelling_model(settings)
                    settings = _demo_camera_mount(settings)
            _check_stages(settings, stages)
            _until_signal(stop, partial(runtime.run, settings, stages=stages, api=True, stop=stop, extra=extra,
                                        compact=True))
        case "worker":
            _check_stages(settings, [args.stage])
            _until_signal(stop, partial(runtime.run, settings, stages=[args.stage], api=False, stop=stop))
        case "serve":
            _until_signal(stop, partial(runtime.run, settings, stages=[], api=True, stop=stop,
                                        expected_workers=settings.stages))
        case "db":
            return _db(args, settings)
        case "settings":
            print(json.dumps(settings.model_dump(mode="json"), indent=2))
        case "replay":
            from shared.bus import Bus

            with Bus.open(settings.zenoh, domain_id=settings.ros_domain_id) as bus, runtime.stop_on_signals(stop):
                _replay_job(bus, stop, bag=args.bag, rate=args.rate, loop=args.loop, namespace=args.namespace)
        case "record":
            from services.replay import record
            from shared.bus import Bus

            with Bus.open(settings.zenoh, domain_id=settings.ros_domain_id) as bus, runtime.stop_on_signals(stop):
                stats = record(bus, args.out, stop=stop, domain_id=settings.ros_domain_id)
            log.info("recorded %s", stats)
        case "import-carmen":
            from services.replay import import_carmen

            log.info("wrote %s: %s", args.out, import_carmen(args.log, args.out))
        case "map-build":
            return _map_build(args, settings)
        case "sim":
            _sim(args, settings, stop)
        case "floor-plan":
            _floor_plan(args)
        case "train-classifier" | "eval-classifier":
            _classifier(args, settings)
        case "keys":
            return _keys(args, settings)
        case "export":
            return _export(args, settings)
    return 0


def _until_signal(stop: threading.Event, run: Callable[[], list[str]]) -> None:
    """``run`` (:func:`services.runtime.run` with ``stop``) until SIGINT or SIGTERM sets ``stop``; the process ends
    at once if it left threads busy (``settings.shutdown_grace_s`` is over: their work in progress is dropped)."""
    from services import runtime

    with runtime.stop_on_signals(stop):
        busy = run()
    if busy:
        runtime.exit_now(0)


def _decompose(args: argparse.Namespace) -> None:
    from shared.collector import collector_held

    with collector_held():  # the package's and its step libraries' imports and one decomposition
        from services.grid_decomposition import decompose_map_file, parse_label_overrides

        overrides = parse_label_overrides(args.labels) if args.labels else None
        decompose_map_file(args.map, args.out, resolution_m=args.resolution, label_overrides=overrides)
        # the command's process ends here: the objects it holds now (the libraries' ~225 000) are never walked again,
        # neither by the next young collection (all of them are young after the hold) nor by the full one at exit;
        # they are still freed when nothing refers to them (a decomposition leaves no reference cycles)
        gc.freeze()
    log.info("wrote the decomposition of %s to %s", args.map, args.out)


def _floor_plan(args: argparse.Namespace) -> None:
    from services.floor_plan import ChainSettings, FloorPlanError, FloorPlanSettings
    from services.floor_plan.mapfile import floor_plan_map_file, read_trajectory

    if args.iterations < 1:
        raise FloorPlanError(f"--iterations must be at least 1, got {args.iterations}")
    chain = ChainSettings(iterations=args.iterations, max_seconds=args.max_seconds, seed=args.seed)
    trajectory = read_trajectory(args.trajectory) if args.trajectory is not None else None
    plan = floor_plan_map_file(args.map, args.out, resolution_m=args.resolution,
                               settings=FloorPlanSettings(chain=chain), trajectory_xy_m=trajectory)
    rate = plan.iterations / plan.seconds if plan.seconds > 0 else float("inf")
    print(f"K(W,M) {100 * plan.k:.2f} % ({100 * plan.k_units:.2f} % the units alone, without {plan.wall_segments} "
          f"fitted wall segments, {plan.slanted_walls} slanted walls, {plan.clutter} clutter and {plan.exterior} "
          "exterior obstacles)  "
          f"units {len(plan.units)}  doors {len(plan.doors)}  "
          f"iterations {plan.iterations}  {rate:.0f} iterations/s  (CPU {plan.cpu_seconds:.2f} s)")


def _keys(args: argparse.Namespace, settings: Settings) -> int:
    from services import runtime
    from shared.store import keys

    store = runtime.open_store(settings)
    try:
        if args.keys_command == "create":
            key_id, secret = keys.create_key(store, role=args.role, name=args.name)
            print(f"{key_id} ({args.role}, {args.name}): {secret}")
            print("Keep the secret now: it is stored only as a hash.", file=sys.stderr)
        elif args.keys_command == "list":
            for key in keys.list_keys(store, include_revoked=args.all):
                revoked = f" revoked {key.revoked_at:%Y-%m-%d %H:%M}" if key.revoked_at else ""
                print(f"{key.key_id}  {key.role:<5}  {key.name}  created {key.created_at:%Y-%m-%d %H:%M}{revoked}")
        elif keys.revoke_key(store, key_id=args.key_id) is None:
            log.error("no key %s", args.key_id)
            return 1
    finally:
        store.close()
    return 0


def _db(args: argparse.Namespace, settings: Settings) -> int:
    """``aisle db``: exit code 2, with the reason on stderr, for an unknown map or revision."""
    from services import runtime

    store = runtime.open_store(settings)
    try:
        if args.db_command == "upgrade":
            log.info("database schema is up to date (%s)", settings.database_url)
            return 0
        if args.db_command == "compact" and args.map is None:
            maps = store.maps()
        else:
            name = args.map or settings.map_name
            found = store.get_map(name)
            if found is None:
                print(f"aisle db: no map named {name!r}; known maps: {[m.name for m in store.maps()]}",
                      file=sys.stderr)
                return 2
            maps = [found]
        if args.db_command == "compact":
            for map_info in maps:
                print(store.compact(map_info.id, settings.retention.policy(), dry_run=args.dry_run).describe())
            if not args.dry_run and store.vacuum():
                print("returned the freed space to the file system (VACUUM)")
            return 0
        if store.pin_revision(maps[0].id, args.revision, pinned=args.db_command == "pin") is None:
            print(f"aisle db: map {maps[0].name!r} has no revision {args.revision}", file=sys.stderr)
            return 2
        print(f"revision {args.revision} of map {maps[0].name!r} {args.db_command}ned")
        return 0
    finally:
        store.close()


def _export(args: argparse.Namespace, settings: Settings) -> int:
    """``aisle export``: exit code 2, with the reason on stderr, for an unknown map, format, revision or layer."""
    from atlas.exports import ExportError, export_to_path
    from services import runtime

    store = runtime.open_store(settings)
    try:
        name = args.map or settings.map_name
        map_info = store.get_map(name)
        if map_info is None:
            print(f"aisle export: no map named {name!r}; known maps: {[m.name for m in store.maps()]}",
                  file=sys.stderr)
            return 2
        try:
            written = export_to_path(store, map_info, args.format, args.out, revision=args.revision,
                                     layer=args.layer)
        except ExportError as err:
            print(f"aisle export: {err}", file=sys.stderr)
            return 2
    finally:
        store.close()
    for path in written:
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


def _classifier(args: argparse.Namespace, settings: Settings) -> None:
    from services.labelling_training.commands import evaluate_from_sources, train_from_sources
    from services.object_labelling.recogniser import model_path_of

    if args.command == "train-classifier":
        out = args.out or model_path_of(settings)
        train_from_sources(out, data_dir=args.data, sim_views=args.sim_views, input_size_px=args.input_size,
                           seed=args.seed, feature_cache=args.feature_cache)
        log.info("wrote %s", out)
    else:
        for title, evaluation in evaluate_from_sources(args.model or model_path_of(settings), data_dir=args.data,
                                                       sim_views=args.sim_views, seed=args.seed,
                                                       feature_cache=args.feature_cache):
            print(f"## {title}\n\n{evaluation.markdown()}\n")


def _pillars(args: argparse.Namespace, settings: Settings) -> None:
    import math

    from services import pillar_mapping

    if args.command == "racks":
        profiles = ([pillar_mapping.rack_profile([float(z) for z in args.levels.split(",")])] if args.levels else
                    [pillar_mapping.rack_profile(p.levels_m, p.area) for p in settings.pillars.rack_profiles])
        layout = pillar_mapping.fit_racks(args.pillars, args.out, profiles=profiles)
        log.info("%d rack rows, %d bins -> %s", len(layout.rows), len(layout.bins), args.out / "racks.geojson")
    elif args.pillars_command == "detect":
        found = pillar_mapping.detect_pillars_file(args.image, args.camera_info)
        for bearing, sigma, strength in zip(found.bearings_rad, found.sigmas_rad, found.strengths, strict=True):
            print(f"{math.degrees(bearing):9.3f} deg  sigma {math.degrees(sigma):6.3f} deg  snr {strength:6.1f}")
    else:
        result = pillar_mapping.map_pillars_from_bag(args.bag, args.out)
        log.info("mapped %d landmarks from %d frames (%d skipped) -> %s", len(result.landmarks.means),
                 result.frames_used, result.frames_skipped, args.out)


def _sim(args: argparse.Namespace, settings: Settings, stop: threading.Event) -> None:
    from services import runtime
    from services.simulator import load_world, sim_live, sim_run, sim_world
    from shared.bus import Bus

    if args.random == (args.layout is not None):
        raise ValueError("name a layout (file or preset) or pass --random, not both")
    if args.sim_command == "world":
        written = sim_world(args.layout, args.out, seed=args.seed, resolution_m=args.resolution)
        log.info("wrote %s", ", ".join(str(path) for path in written.values()))
        return
    world = load_world(args.layout, seed=args.seed)
    cameras = [name for name in args.cameras.split(",") if name]
    if args.live:
        with Bus.open(settings.zenoh, domain_id=settings.ros_domain_id) as bus, runtime.stop_on_signals(stop):
            sim_live(bus, stop, world, robots=args.robots, speed_mps=args.speed, seed=args.seed, cameras=cameras,
                     rate=args.rate)
        return
    counts = sim_run(world, args.out, robots=args.robots, speed_mps=args.speed, seed=args.seed, cameras=cameras)
    log.info("wrote %s: %d messages (%s)", args.out, counts.total(), dict(counts))


def _check_stages(settings: Settings, stages: Sequence[str]) -> None:
    """Fail before starting anything when a stage cannot run (object labelling without a usable model)."""
    if "object_labelling" in stages:
        from services.object_labelling.recogniser import check_recogniser

        check_recogniser(settings)


def _demo_labelling_model(settings: Settings) -> None:
    from services.labelling_training.commands import ensure_demo_model
    from services.object_labelling.recogniser import model_path_of

    ensure_demo_model(model_path_of(settings))


def _demo_settings(settings: Settings) -> Settings:
    """The demo warehouse's rack levels as the site's rack profile and the simulator's localisation error
    (1 cm, 0.002 rad: the pillar map is then smoothed with odometry), unless the settings give them."""
    from services.simulator import demo_layout

    update: dict[str, object] = {}
    if not settings.pillars.rack_profiles:
        block = demo_layout()["blocks"][0]
        levels = [k * float(block["level_pitch_m"]) for k in range(int(block["levels"]))]
        update["rack_profiles"] = [RackProfileSettings(levels_m=levels)]
    if settings.pillars.localisation_sigma_m == 0 and settings.pillars.localisation_sigma_rad == 0:
        update.update(localisation_sigma_m=0.01, localisation_sigma_rad=0.002)
    return settings.model_copy(update={"pillars": settings.pillars.model_copy(update=update)})


def _demo_camera_mount(settings: Settings) -> Settings:
    """The demo RGB-D camera's floor frame (where its annotated scans are posed) in the robot base frame as
    the semantic fusion's camera mount, unless the settings give one: the lidar's scans are placed through it."""
    from services.simulator.cameras import RGBD_MOUNT

    fusion = settings.fusion
    if (fusion.camera_x_in_base_m, fusion.camera_y_in_base_m, fusion.camera_yaw_in_base_rad) != (0.0, 0.0, 0.0):
        return settings
    optical_axis = RGBD_MOUNT[:3, 2]
    update = {"camera_x_in_base_m": float(RGBD_MOUNT[0, 3]), "camera_y_in_base_m": float(RGBD_MOUNT[1, 3]),
              "camera_yaw_in_base_rad": math.atan2(float(optical_axis[1]), float(optical_axis[0]))}
    return settings.model_copy(update={"fusion": fusion.model_copy(update=update)})


def _demo_job(cameras: str, *, rate: float) -> Callable[[Bus, threading.Event], None]:
    from services.simulator import fisheye_sensor, rgbd_sensor, run_demo

    sensors = {"fisheye": lambda: fisheye_sensor(rate_hz=2.0), "rgbd": lambda: rgbd_sensor(rate_hz=2.0)}
    names = [name for name in cameras.split(",") if name]
    unknown = set(names) - set(sensors)
    if unknown:
        raise ValueError(f"unknown demo cameras {sorted(unknown)}; known: {sorted(sensors)}")
    return partial(run_demo, rate=rate, cameras=tuple(sensors[name]() for name in names))


def _replay_job(bus: Bus, stop: threading.Event, *, bag: Path, rate: float, loop: bool,
                namespace: str = "") -> None:
    from services.replay import replay_bag

    stats = replay_bag(bus, bag, rate=rate, loop=loop, stop=stop, namespace=namespace)
    log.info("replay of %s finished: %s", bag, stats)


def _map_build(args: argparse.Namespace, settings: Settings) -> int:
    from services.occupancy_mapping import ScanMatcher, build_map, sharpness
    from shared.mapfiles import write_map_yaml

    occupancy_settings = settings.occupancy
    max_range_m = occupancy_settings.max_range_m
    grid = build_map(
        args.bag,
        resolution_m=args.resolution or occupancy_settings.resolution_m,
        scan_topic=args.scan_topic or occupancy_settings.scan_topic,
        max_range_m=max_range_m,
        corrector=ScanMatcher(max_range_m=max_range_m) if args.scan_matching else None,
    )
    occupancy = grid.occupancy()
    write_map_yaml(args.out, occupancy, resolution_m=grid.resolution_m, origin_x_m=grid.origin_x_m,
                   origin_y_m=grid.origin_y_m)
    log.info("wrote %s (%d x %d cells at %.3f m, sharpness %.3f)", args.out, occupancy.shape[1],
             occupancy.shape[0], grid.resolution_m, sharpness(occupancy))
    return 0


if __name__ == "__main__":
    sys.exit(main())
