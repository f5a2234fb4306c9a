"""Files on disk: layouts in, ground truth out."""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from services.simulator.actors import actor_pose
from services.simulator.errors import SimulatorError
from services.simulator.groundtruth import ground_truth_features, ground_truth_grids, uprights_csv
from services.simulator.world import FloatArray, World
from shared.mapfiles import write_map_yaml

log = logging.getLogger(__name__)


def read_layout(path: Path) -> dict[str, Any]:
    """The layout mapping in YAML file ``path``."""
    try:
        layout = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as err:
        raise SimulatorError(f"cannot read layout {path}: {err}") from err
    if not isinstance(layout, dict):
        raise SimulatorError(f"layout {path} must be a YAML mapping, got {type(layout).__name__}")
    return layout


def actor_tracks(world: World, *, duration_s: float, rate_hz: float = 1.0) -> dict[str, FloatArray]:
    """Each actor's [t, x, y, yaw] samples (n, 4) over the first ``duration_s`` seconds."""
    times = np.arange(0.0, max(duration_s, 0.0) + 1e-9, 1.0 / rate_hz)
    return {a.id: np.array([(t, *actor_pose(a, float(t))) for t in times]) for a in world.actors}


def write_ground_truth(world: World, out_dir: Path, *, resolution_m: float = 0.05, height_m: float = 0.2,
                       tracks: Mapping[str, FloatArray] | None = None) -> dict[str, Path]:
    """Write ``world``'s ground truth into ``out_dir`` (created); return the files by role.

    ``layout.yaml`` (the layout, to rebuild the world), ``world.geojson`` (every feature),
    ``uprights.csv``, ``occupancy.yaml`` + ``.pgm`` (map_server map of the obstacles at ``height_m``)
    and ``labels.png`` (place labels 0..6, pixel for pixel on the occupancy image: top row = highest y).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    grids = ground_truth_grids(world, resolution_m=resolution_m, height_m=height_m)
    files = {
        "layout": out_dir / "layout.yaml",
        "geojson": out_dir / "world.geojson",
        "uprights": out_dir / "uprights.csv",
        "occupancy": out_dir / "occupancy.yaml",
        "labels": out_dir / "labels.png",
    }
    files["layout"].write_text(yaml.safe_dump(json.loads(json.dumps(dict(world.layout))), sort_keys=False))
    files["geojson"].write_text(json.dumps(ground_truth_features(world, tracks=tracks)))
    files["uprights"].write_text(uprights_csv(world))
    write_map_yaml(files["occupancy"], grids.occupancy, resolution_m=grids.resolution_m,
                   origin_x_m=grids.origin_x_m, origin_y_m=grids.origin_y_m)
    if not cv2.imwrite(str(files["labels"]), grids.labels[::-1]):
        raise SimulatorError(f"cannot write {files['labels']}")
    log.info("wrote ground truth of %s (%d uprights, %d bins) to %s", world.name, len(world.uprights.ids),
             len(world.bins), out_dir)
    return files
