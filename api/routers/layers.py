"""Grid layers of a map: metadata, a PNG to look at, and the raw values."""

from __future__ import annotations

import enum
from typing import Annotated, Any

import numpy as np
import numpy.typing as npt
from fastapi import APIRouter, Depends, HTTPException, Path, Query, Response, status

from api.deps import CacheDep, MapDep, RevisionQuery, StoreDep
from api.models import (
    COMMON_ERRORS,
    UNPROCESSABLE,
    ErrorOut,
    LayerOut,
    LayerValuesOut,
    Origin,
    not_found,
)
from atlas.render.layers import RenderError, encode_npy, encode_png, render_layer
from atlas.render.overlay import overlay_image
from shared.store import StoredLayer
from shared.vocabulary import REVISION_HEADER

router = APIRouter(prefix="/v1/maps/{map_name}/layers", tags=["layers"], responses=COMMON_ERRORS)

MAX_JSON_CELLS = 1_000_000
"""Larger layers are refused as JSON (413); fetch them as .npy."""


_NOT_FOUND = not_found("No such map, revision or layer.")


class ValuesFormat(enum.StrEnum):
    NPY = "npy"
    JSON = "json"


def get_layer(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    layer: Annotated[str, Path(description="Layer name, e.g. `occupancy`.", max_length=64, examples=["occupancy"])],
) -> StoredLayer:
    """The layer named in the path as of ``?revision=`` (default: newest), or 404 listing known layers."""
    found = store.layer(map_info.id, layer, revision=revision)
    if found is not None:
        return found
    known = store.layer_names(map_info.id)
    if layer in known:
        detail = (f"layer {layer!r} of map {map_info.name!r} has no version at or before revision {revision} "
                  f"(the store keeps the newest {store.layer_history} versions of each layer)")
    else:
        detail = f"map {map_info.name!r} has no layer {layer!r}; known layers: {known}"
    raise HTTPException(status.HTTP_404_NOT_FOUND, detail)


LayerDep = Annotated[StoredLayer, Depends(get_layer)]


def layer_out(stored: StoredLayer) -> LayerOut:
    layer = stored.layer
    rows, cols = layer.data.shape
    return LayerOut(
        name=layer.name,
        revision_id=stored.revision_id,
        dtype=layer.data.dtype.name,
        shape=(rows, cols),
        resolution_m=layer.resolution_m,
        origin=Origin(x_m=layer.origin_x_m, y_m=layer.origin_y_m),
        extent=(layer.origin_x_m, layer.origin_y_m,
                layer.origin_x_m + cols * layer.resolution_m, layer.origin_y_m + rows * layer.resolution_m),
        meta=dict(layer.meta),
    )


@router.get("", summary="List layers", responses={**_NOT_FOUND, **UNPROCESSABLE})
def list_layers(map_info: MapDep, store: StoreDep, revision: RevisionQuery) -> list[LayerOut]:
    """Every grid layer of the map (as of ``?revision=``) with its shape, resolution and origin."""
    found = (store.layer(map_info.id, name, revision=revision) for name in store.layer_names(map_info.id))
    return [layer_out(stored) for stored in found if stored is not None]


@router.get(
    "/{layer}.png",
    summary="Layer as an image",
    response_class=Response,
    responses={
        status.HTTP_200_OK: {"content": {"image/png": {}},
                             "description": "PNG, top row = highest y: colour with a legend for semantic "
                                            "label layers, greyscale otherwise."},
        status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut,
                                                "description": "Layer cannot be drawn, or a bad parameter."},
        **_NOT_FOUND,
    },
)
def layer_png(stored: LayerDep) -> Response:
    """The layer as a PNG, north up: the top row of the image is the highest y, one pixel a cell.

    Semantic label layers (meta ``encoding`` = ``semantic_labels``) are drawn in their classes'
    colours with a legend of the classes present to the right. Occupancy (int8) is drawn as
    map_server does: unknown grey 205, free white, occupied black, shaded by probability in
    between. Other layers are scaled min-max to black..white.
    """
    try:
        png = encode_png(render_layer(stored.layer.data, stored.layer.meta))
    except RenderError as err:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err)) from err
    return Response(png, media_type="image/png", headers={REVISION_HEADER: str(stored.revision_id)})


@router.get(
    "/{layer}/overlay.png",
    summary="Layer as a transparent overlay",
    response_class=Response,
    responses={
        status.HTTP_200_OK: {"content": {"image/png": {}},
                             "description": "RGBA PNG, top row = highest y, one pixel a cell, no legend."},
        status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut,
                                                "description": "Layer cannot be drawn, or a bad parameter."},
        **_NOT_FOUND,
    },
)
def layer_overlay_png(
    map_info: MapDep,
    store: StoreDep,
    cache: CacheDep,
    revision: RevisionQuery,
    stored: LayerDep,
    entropy: Annotated[str | None, Query(max_length=64, examples=["semantic_entropy"], description=(
        "An entropy layer (values 0..1, negative where there is no data) of the same shape: each cell is drawn "
        "the more transparent the less certain it is."))] = None,
) -> Response:
    """The layer as an RGBA PNG to lay over other layers in a map viewer, north up, one pixel a cell: label
    layers in their classes' colours with unlabelled cells transparent, occupancy as map_saver greys with unknown
    cells transparent, other layers as greys. With ``?entropy=``, a label's opacity is its certainty
    (1 - entropy), as the viewer shows the semantic labels. The image covers the layer's `extent`
    (`GET …/layers/{layer}`)."""
    uncertainty = None if entropy is None else get_layer(map_info, store, revision, entropy)

    def draw() -> bytes:
        certainty = None
        if uncertainty is not None:
            values = uncertainty.layer.data
            certainty = np.where(values < 0, -1.0, 1.0 - values.astype(np.float64))
        return encode_png(overlay_image(stored.layer.data, stored.layer.meta, certainty=certainty))

    key = ("overlay", map_info.id, stored.layer.name, stored.revision_id,
           None if uncertainty is None else (uncertainty.layer.name, uncertainty.revision_id))
    try:
        png = cache.get(key, draw)  # every viewer asks for the same picture of a layer version
    except RenderError as err:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err)) from err
    return Response(png, media_type="image/png", headers={REVISION_HEADER: str(stored.revision_id)})


@router.get(
    "/{layer}/values",
    summary="Layer values",
    response_model=LayerValuesOut,
    responses={
        status.HTTP_200_OK: {"content": {"application/x-npy": {}},
                             "description": "A .npy file (format=npy) or JSON (format=json)."},
        status.HTTP_413_CONTENT_TOO_LARGE: {"model": ErrorOut, "description": "Too many cells for JSON."},
        status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut,
                                                "description": "No JSON form (complex), or a bad parameter."},
        **_NOT_FOUND,
    },
)
def layer_values(
    map_info: MapDep,
    stored: LayerDep,
    value_format: Annotated[ValuesFormat, Query(alias="format", description="npy (default) or json.",
                                                examples=["json"])] = (
        ValuesFormat.NPY
    ),
) -> Response | LayerValuesOut:
    """The raw cell values, ``data[row, col]`` with row 0 the lowest y.

    ``npy`` is a numpy ``.npy`` file (read with ``numpy.load(..., allow_pickle=False)``); ``json``
    is for small layers only (at most 1 000 000 cells).
    """
    layer = stored.layer
    if value_format is ValuesFormat.NPY:
        filename = f"{map_info.name}_{layer.name}_r{stored.revision_id}.npy"
        return Response(
            encode_npy(layer.data),
            media_type="application/x-npy",
            headers={REVISION_HEADER: str(stored.revision_id),
                     "Content-Disposition": f'attachment; filename="{filename}"'},
        )
    if layer.data.size > MAX_JSON_CELLS:
        raise HTTPException(
            status.HTTP_413_CONTENT_TOO_LARGE,
            f"layer {layer.name!r} has {layer.data.size} cells, more than {MAX_JSON_CELLS} allowed as JSON; "
            "use ?format=npy",
        )
    return LayerValuesOut(**layer_out(stored).model_dump(), data=_json_values(layer.data))


def _json_values(data: npt.NDArray[Any]) -> list[list[Any]]:
    if data.dtype.kind not in "biuf":
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                            f"layers of dtype {data.dtype.name} have no JSON form; use ?format=npy")
    if data.dtype.kind == "f":
        cells = data.astype(object)
        cells[~np.isfinite(data)] = None
        return list(cells.tolist())
    return list(data.tolist())


@router.get("/{layer}", summary="Describe a layer", responses={**_NOT_FOUND, **UNPROCESSABLE})
def get_layer_info(stored: LayerDep) -> LayerOut:
    """Shape, dtype, resolution, origin and metadata of one layer version."""
    return layer_out(stored)
