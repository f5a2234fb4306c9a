"""Read and write ROS map_server maps (YAML + PGM/PNG image).

The occupancy mapper writes them (``aisle map build``), the grid decomposition and the benchmarks read
them, and the simulator writes its ground truth as one.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
import yaml
from PIL import Image, UnidentifiedImageError

FREE_PIXEL = 254
MODE_SHARE = 0.01
"""A grey value is a mode of a bare map image (its white, its unknown grey) when at least this share of the
pixels has it: unknown and free space are drawn in one grey each, speckle spreads over many."""
MODE_GAP = 8
"""The unknown grey is darker than the white mode by at least this much (the white mode's own spread)."""
OCCUPIED_PIXEL = 0
UNKNOWN_PIXEL = 205


class MapFileError(ValueError):
    """A map file that cannot be read or a map that cannot be written: missing, malformed, bad geometry."""


IMAGE_SUFFIXES = frozenset({".png", ".pgm", ".ppm", ".bmp", ".tif", ".tiff", ".jpg", ".jpeg"})
"""Suffixes of the bare map images :func:`read_map_file` reads."""


class MapImage(NamedTuple):
    """A map read from disk: occupancy int8 (-1 unknown, 0..100), GridLayer row order (row 0 = lowest y)."""

    occupancy: npt.NDArray[np.int8]
    resolution_m: float
    origin_x_m: float
    origin_y_m: float


def write_map_yaml(
    path_yaml: Path,
    occupancy: npt.NDArray[np.int8],
    *,
    resolution_m: float,
    origin_x_m: float,
    origin_y_m: float,
    occupied_percent: int = 65,
    free_percent: int = 25,
) -> Path:
    """Write ``occupancy`` as a trinary map_server map (creating its folder); return the image path.

    The image (same stem, ``.pgm``) has free 254 (cells below ``free_percent``), occupied 0 (above
    ``occupied_percent``), unknown 205 (the rest), and its top row is the grid's last (highest-y)
    row. The YAML says ``free_thresh: 0.196`` like ROS 1 map_saver, so that 205 reads back as
    unknown under either threshold convention.
    """
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or 0 in occ.shape:
        raise MapFileError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
    if not (
        math.isfinite(resolution_m)
        and resolution_m > 0
        and math.isfinite(origin_x_m)
        and math.isfinite(origin_y_m)
    ):
        raise MapFileError(
            f"bad map geometry: resolution {resolution_m}, origin ({origin_x_m}, {origin_y_m})"
        )
    if not 0 <= free_percent < occupied_percent <= 100:
        raise MapFileError(
            f"need 0 <= free_percent < occupied_percent <= 100, got {free_percent}, {occupied_percent}"
        )
    path_yaml = Path(path_yaml)
    path_image = path_yaml.with_suffix(".pgm")
    path_yaml.parent.mkdir(parents=True, exist_ok=True)
    pixels = np.full(occ.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    known = occ >= 0
    pixels[known & (occ > occupied_percent)] = OCCUPIED_PIXEL
    pixels[known & (occ < free_percent)] = FREE_PIXEL
    Image.fromarray(pixels[::-1]).save(path_image)
    meta = {
        "image": path_image.name,
        "mode": "trinary",
        "resolution": float(resolution_m),
        "origin": [float(origin_x_m), float(origin_y_m), 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    path_yaml.write_text(yaml.safe_dump(meta, sort_keys=False))
    return path_image


def _load_yaml(path: Path) -> dict[str, Any]:
    try:
        meta = yaml.safe_load(path.read_text())
    except FileNotFoundError as err:
        raise MapFileError(f"map file {path} does not exist") from err
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise MapFileError(f"map file {path} is not readable YAML: {err}") from err
    if not isinstance(meta, dict):
        raise MapFileError(f"map file {path} is not a YAML mapping")
    missing = {"image", "resolution", "origin"} - set(meta)
    if missing:
        raise MapFileError(f"map file {path} lacks {sorted(missing)}")
    return meta


def read_map_yaml(path: Path) -> MapImage:
    """Read a map_server map, honouring ``negate``, ``occupied_thresh``, ``free_thresh`` and ``mode``.

    ``trinary`` and ``raw`` give -1/0/100 and raw pixel values respectively; ``scale`` gives the
    probability in percent between the thresholds, as map_server does. A non-zero origin yaw is
    rejected (the grid layer has none).
    """
    path = Path(path)
    meta = _load_yaml(path)
    try:
        resolution = float(meta["resolution"])
        origin_x, origin_y, yaw = (float(v) for v in meta["origin"])
        negate = bool(int(meta.get("negate", 0)))
        occupied_thresh = float(meta.get("occupied_thresh", 0.65))
        free_thresh = float(meta.get("free_thresh", 0.196))
    except (TypeError, ValueError) as err:
        raise MapFileError(f"map file {path}: bad resolution/origin/thresholds: {err}") from err
    mode = str(meta.get("mode", "trinary"))
    if mode not in {"trinary", "scale", "raw"}:
        raise MapFileError(f"map file {path}: unknown mode {mode!r}")
    if not (math.isfinite(resolution) and resolution > 0):
        raise MapFileError(f"map file {path}: resolution {resolution} must be positive")
    if abs(yaw) > 1e-9:
        raise MapFileError(f"map file {path}: origin yaw {yaw} rad is not supported")
    image_path = path.parent / str(meta["image"])
    try:
        with Image.open(image_path) as image:
            has_alpha = "A" in image.getbands()
            pixels = np.asarray(image.convert("LA" if has_alpha else "L"), dtype=np.float64)
    except FileNotFoundError as err:
        raise MapFileError(f"map image {image_path} does not exist") from err
    except (OSError, UnidentifiedImageError) as err:
        raise MapFileError(f"map image {image_path} is not a readable image: {err}") from err
    alpha = pixels[..., 1] if has_alpha else None
    value = pixels[..., 0] if has_alpha else pixels
    if mode == "raw":
        occ = np.clip(value, -1, 100).astype(np.int8)
        return MapImage(occ[::-1].copy(), resolution, origin_x, origin_y)
    p = value / 255.0 if negate else (255.0 - value) / 255.0
    occ = np.full(value.shape, -1, dtype=np.int8)
    occ[p > occupied_thresh] = 100
    occ[p < free_thresh] = 0
    if mode == "scale":
        between = (p >= free_thresh) & (p <= occupied_thresh)
        scaled = 99.0 * (p - free_thresh) / (occupied_thresh - free_thresh)
        occ[between] = np.rint(scaled[between]).astype(np.int8)
        if alpha is not None:
            occ[alpha < 1.0] = -1
    return MapImage(occ[::-1].copy(), resolution, origin_x, origin_y)


__all__ = [
    "FREE_PIXEL",
    "OCCUPIED_PIXEL",
    "UNKNOWN_PIXEL",
    "MapFileError",
    "MapImage",
    "free_grey_threshold",
    "read_map_yaml",
    "write_map_yaml",
]


def free_grey_threshold(grey: npt.NDArray[np.number[Any]]) -> float:
    """The grey above which a pixel of a bare map image is free: midway between the image's unknown grey and its
    white, and never below map_server's free threshold (darkness 0.196, grey 204.02).

    Map images mark unknown space with a grey of their own (ROS 205, others 153, 178, 230) and free space white;
    light-grey speckle between the two (cells seen free a few times) is nearer one or the other. The white is
    the lightest grey held by at least :data:`MODE_SHARE` of the pixels; the unknown grey the most common one
    between map_server's occupied threshold (darkness 0.65) and :data:`MODE_GAP` below the white, if one holds
    that share. Without such a grey (a map drawn in black and white only) map_server's threshold stands.

    >>> grey = np.r_[np.full(60, 255), np.full(30, 230), np.full(10, 0)]
    >>> free_grey_threshold(grey)
    242.5
    """
    values = np.clip(np.rint(np.asarray(grey, np.float64)), 0, 255).astype(np.int64).ravel()
    share = np.bincount(values, minlength=256) / max(values.size, 1)
    floor = 255.0 * (1.0 - 0.196)
    common = np.flatnonzero(share >= MODE_SHARE)
    if common.size == 0:
        return floor
    white = int(common.max())
    band = np.arange(256)
    band = band[(band > 255.0 * (1.0 - 0.65)) & (band <= white - MODE_GAP)]
    if band.size == 0 or share[band].max() < MODE_SHARE:
        return floor
    unknown = int(band[np.argmax(share[band])])
    return max(floor, (unknown + white) / 2.0)


def read_map_file(path: Path, *, resolution_m: float | None = None, free_darkness: bool = False,
                  free_from_modes: bool = False) -> MapImage:
    """A map_server YAML (:func:`read_map_yaml`) or a bare map image.

    A bare image is read with map_server's trinary thresholds (darkness above 0.65 occupied, below 0.196 free, the
    rest unknown) and needs ``resolution_m``; its origin is (0, 0). With ``free_darkness`` its free cells keep their
    darkness in percent (0..19, rounded down) instead of 0, so grey fringes at walls can be told from clear floor.
    With ``free_from_modes`` a bare image's free cells must also be nearer its white than its unknown grey
    (:func:`free_grey_threshold`): maps drawn with a light unknown grey (230) and light-grey speckle read right.
    For a YAML, ``resolution_m`` (if given) must match the file's.

    Raises
    ------
    MapFileError
        Missing or unreadable files, malformed YAML, a bare image without a resolution, a resolution that disagrees.
    """
    path = Path(path)
    if not path.exists():
        raise MapFileError(f"map file {path} does not exist")
    if path.suffix.lower() in {".yaml", ".yml"}:
        image = read_map_yaml(path)
        if resolution_m is not None and not math.isclose(resolution_m, image.resolution_m, rel_tol=1e-6):
            raise MapFileError(f"--resolution {resolution_m} m disagrees with {path}'s resolution "
                               f"{image.resolution_m} m")
        return image
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise MapFileError(f"map file {path} is neither a map_server YAML nor an image ({sorted(IMAGE_SUFFIXES)})")
    if resolution_m is None:
        raise MapFileError(f"map image {path} has no YAML: give its resolution in metres per pixel")
    try:
        with Image.open(path) as im:
            grey = np.asarray(im.convert("L"), dtype=np.float64)
    except (OSError, UnidentifiedImageError) as err:
        raise MapFileError(f"map image {path} is not a readable image: {err}") from err
    darkness = (255.0 - grey) / 255.0
    occupancy = np.full(grey.shape, -1, dtype=np.int8)
    occupancy[darkness > 0.65] = 100
    free = darkness < 0.196
    if free_from_modes:
        free &= grey > free_grey_threshold(grey)
    occupancy[free] = np.floor(darkness[free] * 100.0).astype(np.int8) if free_darkness else 0
    return MapImage(occupancy[::-1].copy(), float(resolution_m), 0.0, 0.0)
