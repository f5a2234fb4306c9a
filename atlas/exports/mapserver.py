"""Any grid layer as a ROS map_server map: a YAML file and a PGM image.

Occupancy layers (int8, -1 unknown, 0..100 percent) are written as ``map_saver`` writes them in
``trinary`` mode: free 254 (at most 25 %), occupied 0 (at least 65 %), unknown 205 (the rest).
Label layers (unsigned integer codes such as ``place_labels`` and ``semantic_label``) are written
as their codes in ``raw`` mode, and every other numeric layer (entropy, traversability, ...) is
scaled onto the pixel range in ``scale`` mode with the value range in the YAML. PGM row 0 is the
top of the map (the highest y), so the layer's rows are flipped; the YAML origin is the layer's.
Besides map_server's keys, the YAML carries an ``aisle`` mapping (map, layer, revision, dtype, how
pixels map to values), which map_server ignores.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import yaml

from atlas.exports.base import Export, ExportError, ExportNotFoundError, ExportOptions
from atlas.render.layers import FREE_PERCENT, OCCUPIED_PERCENT, UNKNOWN_GREY
from shared.store import GridLayer, MapInfo, MapStore
from shared.vocabulary import LayerName

DEFAULT_LAYER = LayerName.OCCUPANCY.value
"""The layer exported when none is asked for."""
FREE_PIXEL = 254
OCCUPIED_PIXEL = 0
OCCUPIED_THRESH = OCCUPIED_PERCENT / 100.0
FREE_THRESH = 0.196
"""map_server's ``free_thresh`` in the YAML. Unknown grey 205 is 1 - 205/255 = 0.196 occupied, and map_server
reads a pixel as free when it is *below* ``free_thresh``: the 0.25 that nav2's map_saver writes would read every
unknown cell back as free, so, as ROS 1 map_saver does, the YAML says 0.196 and unknown stays unknown under
both ROS 1 and ROS 2 (nav2) map_server."""
SCALE_TOP_PIXEL = 254
"""In ``scale`` mode the smallest finite value is pixel 0 and the largest 254."""
NO_DATA_PIXEL = 255
"""In ``scale`` mode, the pixel of cells without a value (non-finite, or the layer's ``meta['no_data']``)."""
MEDIA_TYPE = "application/yaml"


def occupancy_pixels(occupancy: npt.NDArray[np.int8]) -> npt.NDArray[np.uint8]:
    """map_server ``trinary`` pixels of an occupancy grid, top row = highest y.

    Parameters
    ----------
    occupancy : (rows, cols) int8
        -1 unknown, else occupancy in percent (0..100); row 0 the lowest y. Values outside
        -1..100 are unknown.

    Returns
    -------
    (rows, cols) uint8
        254 free (0..25 %), 0 occupied (65..100 %), 205 unknown or undecided.

    Examples
    --------
    >>> occupancy_pixels(np.array([[0], [50], [100], [-1]], np.int8))[:, 0].tolist()
    [205, 0, 205, 254]
    """
    pixels = np.full(occupancy.shape, UNKNOWN_GREY, dtype=np.uint8)
    known = (occupancy >= 0) & (occupancy <= 100)
    pixels[known & (occupancy <= FREE_PERCENT)] = FREE_PIXEL
    pixels[known & (occupancy >= OCCUPIED_PERCENT)] = OCCUPIED_PIXEL
    return np.ascontiguousarray(pixels[::-1])


def _no_data(layer: GridLayer, values: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    missing = ~np.isfinite(values)
    marker = layer.meta.get("no_data")
    if isinstance(marker, int | float) and not isinstance(marker, bool):
        missing |= values == float(marker)
    return missing


def _scaled(layer: GridLayer) -> tuple[npt.NDArray[np.uint8], dict[str, Any]]:
    values = layer.data.astype(np.float64)
    missing = _no_data(layer, values)
    pixels = np.full(values.shape, NO_DATA_PIXEL, dtype=np.uint8)
    low = high = None
    if not missing.all():
        low, high = float(values[~missing].min()), float(values[~missing].max())
        span = high - low if high > low else 1.0
        pixels[~missing] = np.rint((values[~missing] - low) / span * SCALE_TOP_PIXEL).astype(np.uint8)
    meta = {"value_min": low, "value_max": high, "no_data_pixel": NO_DATA_PIXEL,
            "value_of_pixel": f"value_min + pixel / {SCALE_TOP_PIXEL} * (value_max - value_min); "
                              f"{NO_DATA_PIXEL}: no value"}
    return np.ascontiguousarray(pixels[::-1]), meta


def _is_codes(data: npt.NDArray[Any]) -> bool:
    if data.dtype.kind == "b":
        return True
    if data.dtype.kind not in "iu":
        return False
    return int(data.min()) >= 0 and int(data.max()) <= np.iinfo(np.uint16).max


def layer_pixels(layer: GridLayer) -> tuple[npt.NDArray[Any], str, dict[str, Any]]:
    """The PGM pixels (top row = highest y), the map_server mode and the ``aisle`` YAML meta of a layer.

    int8 layers are occupancy (``trinary``); boolean and integer layers whose values all lie in
    0..65535 are codes (``raw``: uint8 pixels, or uint16 when a code exceeds 255, which map_server
    itself cannot read); other real-valued layers are ``scale``.

    Raises
    ------
    ExportError
        A layer that is not numeric (complex values).
    """
    data = layer.data
    if data.dtype == np.int8:
        return occupancy_pixels(data), "trinary", {"pixels": "254 free, 0 occupied, 205 unknown"}
    if _is_codes(data):
        dtype = np.uint8 if int(data.max()) <= np.iinfo(np.uint8).max else np.uint16
        meta: dict[str, Any] = {"pixels": "the layer's values (codes)"}
        classes = layer.meta.get("classes")
        if isinstance(classes, list) and all(isinstance(name, str) for name in classes):
            meta["classes"] = classes
        return np.ascontiguousarray(data[::-1].astype(dtype)), "raw", meta
    if data.dtype.kind not in "iuf":
        raise ExportError(f"layer {layer.name!r} holds {data.dtype.name} values, which have no map_server form")
    pixels, meta = _scaled(layer)
    return pixels, "scale", meta


def encode_pgm(pixels: npt.NDArray[Any]) -> bytes:
    """Binary (P5) PGM bytes of a uint8 or uint16 image (16-bit samples big-endian, as PGM wants)."""
    ok, buffer = cv2.imencode(".pgm", pixels)
    if not ok:
        raise ExportError(f"PGM encoding failed for an image of shape {pixels.shape} and dtype {pixels.dtype}")
    return bytes(buffer.tobytes())


def map_server_files(layer: GridLayer, *, stem: str, about: Mapping[str, Any]) -> dict[str, bytes]:
    """``<stem>.yaml`` and ``<stem>.pgm`` of a layer, the YAML naming the PGM beside it.

    Parameters
    ----------
    layer : GridLayer
        Any numeric grid layer (see :func:`layer_pixels` for how each kind is written).
    stem : str
        File-name stem of both files.
    about : mapping
        Written first into the YAML's ``aisle`` mapping (e.g. map name and revision id).

    Returns
    -------
    dict
        ``{"<stem>.yaml": ..., "<stem>.pgm": ...}``, YAML first.
    """
    pixels, mode, meta = layer_pixels(layer)
    image = f"{stem}.pgm"
    document = {
        "image": image,
        "mode": mode,
        "resolution": float(layer.resolution_m),
        "origin": [float(layer.origin_x_m), float(layer.origin_y_m), 0.0],
        "negate": 0,
        "occupied_thresh": OCCUPIED_THRESH,
        "free_thresh": FREE_THRESH,
        "aisle": {key: value for key, value in {**about, "layer": layer.name, "dtype": layer.data.dtype.name,
                                                 "encoding": layer.meta.get("encoding"), **meta}.items()
                  if value is not None},
    }
    rows, cols = layer.data.shape
    header = (f"# Aisle layer {layer.name!r}: {cols} x {rows} cells of {layer.resolution_m:g} m, "
              f"map_server mode {mode}\n")
    text = header + yaml.safe_dump(document, sort_keys=False, default_flow_style=None, allow_unicode=True)
    return {f"{stem}.yaml": text.encode(), image: encode_pgm(pixels)}


def export_map_server(store: MapStore, map_info: MapInfo, revision: int, options: ExportOptions) -> Export:
    """The ``map_server`` export: layer ``options.layer`` (default ``occupancy``) as of ``revision``.

    Raises
    ------
    ExportNotFoundError
        The map has no such layer, or none at or before ``revision``; the message lists the layers it has.
    """
    name = options.layer or DEFAULT_LAYER
    stored = store.layer(map_info.id, name, revision=revision)
    if stored is None:
        known = store.layer_names(map_info.id)
        if name in known:
            raise ExportNotFoundError(f"layer {name!r} of map {map_info.name!r} has no version at or before "
                                      f"revision {revision}")
        raise ExportNotFoundError(f"map {map_info.name!r} has no layer {name!r}; known layers: {known}")
    about = {"map": map_info.name, "frame_id": map_info.frame_id, "revision_id": stored.revision_id}
    return Export(map_server_files(stored.layer, stem=options.stem, about=about), MEDIA_TYPE)
