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
"""A grey value is a mode of a bare map image (drawn on purpose: its white, its unknown grey, walls filled grey)
when at least this share of the pixels has it; speckle spreads over many values."""
MODE_GAP = 8
"""The spread of a mode: the unknown grey lies at least this far below the white, and greys this near the
unknown grey are unknown too."""
OCCUPIED_PIXEL = 0
UNKNOWN_PIXEL = 205
WALL_LINE_M = 4.0
"""A light-grey mode's piece is a wall drawn grey when its skeleton is at least this long: walls run on for
metres through a building, furniture drawn in the same grey (desks, bins, table legs) is shorter."""
WALL_WIDTH_M = 0.6
"""... and when it is at most this wide on average (a wall, not a filled light-grey area)."""
WALL_EDGE_M = 0.1
"""A light-grey wall's drawn outline and antialiased edge: the pixels this near it, through pixels that are not
white, are wall too."""


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
    "grey_walls",
    "read_map_yaml",
    "unknown_greys",
    "write_map_yaml",
]


def unknown_greys(grey: npt.NDArray[np.number[Any]]) -> npt.NDArray[np.bool_]:
    """Which greys (a lookup table of 256) of a bare map image are unknown space although map_server's thresholds
    would call them free: the image's own unknown grey and its spread, and the speckle not nearer white than it.

    Map images mark unknown space with a grey of their own (ROS 205, others 153, 178, 230) and free space white.
    A grey held by at least :data:`MODE_SHARE` of the pixels is drawn on purpose (unknown, free, walls or furniture
    filled light grey); greys held by fewer are speckle, cells seen free only a few times. The white is the
    lightest mode; the unknown grey the most common mode between map_server's occupied threshold (darkness 0.65)
    and :data:`MODE_GAP` below the white. A grey within :data:`MODE_GAP` of a mode reads as the nearest mode
    (its spread: antialiasing, noise): unknown for the unknown grey and the modes near it, map_server's reading for
    the others (white, walls or furniture filled grey). Speckle further from every mode is unknown unless it is
    nearer the white than the unknown grey. Without an unknown grey (a map drawn in black and white only) the
    table is all False: map_server's reading stands.

    >>> grey = np.r_[np.full(120, 255), np.full(60, 230), np.full(19, 0), [240]]
    >>> unknown_greys(grey)[[215, 230, 240, 243, 255]].tolist()
    [True, True, True, False, False]
    """
    values = np.clip(np.rint(np.asarray(grey, np.float64)), 0, 255).astype(np.int64).ravel()
    share = np.bincount(values, minlength=256) / max(values.size, 1)
    levels = np.arange(256)
    modes = share >= MODE_SHARE
    if not modes.any():
        return np.zeros(256, bool)
    white = int(levels[modes].max())
    band = (levels > 255.0 * (1.0 - 0.65)) & (levels <= white - MODE_GAP) & modes
    if not band.any():
        return np.zeros(256, bool)
    unknown = int(levels[band][np.argmax(share[band])])
    # a mode is unknown when it lies within MODE_GAP of the unknown grey or map_server does not call it free
    mode_levels = levels[modes]
    mode_unknown = (np.abs(mode_levels - unknown) <= MODE_GAP) | (mode_levels <= 255.0 * (1.0 - 0.196))
    gap = np.abs(levels[:, None] - mode_levels[None, :])
    nearest = np.argmin(gap, axis=1)
    near_mode = gap[levels, nearest] <= MODE_GAP
    out: npt.NDArray[np.bool_] = np.where(near_mode, mode_unknown[nearest], levels - unknown < white - levels)
    return out


def grey_walls(grey: npt.NDArray[np.number[Any]], *, resolution_m: float) -> npt.NDArray[np.bool_]:
    """Which pixels of a bare map image are walls drawn light grey (filled with a grey map_server reads as free).

    Some maps fill their walls with a light grey of their own (ipa's Freiburg52: 211, between a darker outline),
    the same grey other maps use for furniture. A grey mode (:data:`MODE_SHARE` of the pixels) that map_server
    reads as free, lies more than :data:`MODE_GAP` below the white and is not the unknown grey's
    (:func:`unknown_greys`) is a candidate; its pixels (with its spread, :data:`MODE_GAP`) are walls where they
    form lines: 8-connected pieces whose skeleton is at least :data:`WALL_LINE_M` long, at most
    :data:`WALL_WIDTH_M` wide on average (area over skeleton length) and wider than one pixel (a one-pixel line
    is the antialiased edge of a black wall). Their drawn outline and antialiased edge (darker or lighter greys
    that map_server reads as unknown or free) are wall too: the pixels within :data:`WALL_EDGE_M` of such a line,
    reached through pixels that are not the white's. Furniture in the same grey (desks, bins, legs) is shorter
    and stays free. Without such a mode (every map drawn in black, white and an unknown grey) nothing is a wall.

    Parameters
    ----------
    grey : (H, W) number
        The image's grey values, 0..255.
    resolution_m : float
        Metres per pixel.

    Returns
    -------
    (H, W) bool
        True where a light-grey wall is drawn.
    """
    from scipy import ndimage  # imported when first needed
    from skimage.morphology import skeletonize

    values = np.clip(np.rint(np.asarray(grey, np.float64)), 0, 255).astype(np.intp)
    share = np.bincount(values.ravel(), minlength=256) / max(values.size, 1)
    levels = np.arange(256)
    modes = levels[share >= MODE_SHARE]
    walls = np.zeros(values.shape, bool)
    if modes.size == 0:
        return walls
    unknown = unknown_greys(values)
    free_grey = (255.0 - levels) / 255.0 < 0.196
    candidates = [m for m in modes if free_grey[m] and not unknown[m] and m <= modes.max() - MODE_GAP]
    for mode in candidates:
        mask = (np.abs(levels - mode) <= MODE_GAP) & free_grey & ~unknown
        pieces = mask[values]
        parts, n = ndimage.label(pieces, structure=np.ones((3, 3), bool))
        n += 1
        skeleton = skeletonize(pieces)  # type: ignore[no-untyped-call]  # skimage is untyped
        length = np.bincount(parts[skeleton], minlength=n).astype(np.float64)
        area = np.bincount(parts.ravel(), minlength=n).astype(np.float64)
        width = area / np.maximum(length, 1.0)
        line = (length * resolution_m >= WALL_LINE_M) & (width > 1.5) & (width * resolution_m <= WALL_WIDTH_M)
        line[0] = False
        walls |= line[parts]
    if walls.any():
        not_white = np.abs(values - modes.max()) > MODE_GAP
        edge = max(1, round(WALL_EDGE_M / resolution_m))
        walls = ndimage.binary_dilation(walls, structure=np.ones((3, 3), bool), iterations=edge, mask=not_white)
    return np.asarray(walls, bool)


def read_map_file(path: Path, *, resolution_m: float | None = None, free_darkness: bool = False,
                  free_from_modes: bool = False) -> MapImage:
    """A map_server YAML (:func:`read_map_yaml`) or a bare map image.

    A bare image is read with map_server's trinary thresholds (darkness above 0.65 occupied, below 0.196 free, the
    rest unknown) and needs ``resolution_m``; its origin is (0, 0). With ``free_darkness`` its free cells keep their
    darkness in percent (0..19, rounded down) instead of 0, so grey fringes at walls can be told from clear floor.
    With ``free_from_modes`` a bare image's own unknown grey and the speckle nearer it than white are unknown
    (:func:`unknown_greys`), and walls drawn light grey are occupied (:func:`grey_walls`): maps drawn with a light
    unknown grey (230), light-grey speckle or light-grey walls read right.
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
        free &= ~unknown_greys(grey)[np.clip(np.rint(grey), 0, 255).astype(np.intp)]
        walls = grey_walls(grey, resolution_m=float(resolution_m))
        occupancy[walls] = 100
        free &= ~walls
    occupancy[free] = np.floor(darkness[free] * 100.0).astype(np.int8) if free_darkness else 0
    return MapImage(occupancy[::-1].copy(), float(resolution_m), 0.0, 0.0)
