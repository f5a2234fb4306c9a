"""Standard exports of a map (GeoJSON, ROS map_server, ...) as files to download."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, Response, status
from pydantic import BaseModel, Field

from api.deps import MapDep, RevisionQuery, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, ErrorOut, example_config, not_found
from atlas.exports import (
    EXPORT_FORMATS,
    ExportError,
    ExportNotFoundError,
    ExportOptions,
    export_format,
    export_map,
    export_revision,
    export_stem,
    zip_files,
)
from atlas.exports.mapserver import DEFAULT_LAYER
from atlas.layout import LAYOUT_EXAMPLE
from shared.vocabulary import REVISION_HEADER

_LIF_EXAMPLE = {
    "metaInformation": {"projectIdentification": "Aisle", "creator": "Aisle",
                        "exportTimestamp": "2025-03-04T10:15:00.00Z", "lifVersion": "1.0.0"},
    "layouts": [{"layoutId": "site", "layoutName": "site", "layoutVersion": "1207", "layoutLevelId": "L1",
                 "nodes": [{"nodeId": "j3", "nodePosition": {"x": 12.5, "y": 4.0},
                            "vehicleTypeNodeProperties": [{"vehicleTypeId": "aisle.default"}]}],
                 "edges": [], "stations": []}],
}
_RMF_EXAMPLE = ("building_name: site\nlevels:\n  L1:\n    vertices:\n    - [12.5, 4.0, {name: j3}]\n"
                "    - [20.0, 4.0, {name: dock-G1, is_parking_spot: true}]\n    lanes:\n    - [0, 1, {}]\n"
                "    - [1, 0, {}]\nlifts: {}\ndoors: {}\n")

router = APIRouter(prefix="/v1/maps/{map_name}/exports", tags=["exports"], responses=COMMON_ERRORS)


class ExportFormatOut(BaseModel):
    name: str = Field(description="What to ask for: `/exports/<name>`.")
    description: str
    extension: str = Field(description="Extension of the file `/exports/<name>` serves, e.g. `.geojson`, or `.zip` "
                                       "for a format of several files.")
    media_type: str = Field(description="Content-Type `/exports/<name>` serves, e.g. `application/zip`.")
    files: list[str] = Field(description="Extensions of the files the format makes, main file first (inside the "
                                         "zip for several; `aisle export --out` writes them side by side).")
    options: list[str] = Field(description="Query options the format takes besides `revision`, e.g. `layer`.")

    model_config = example_config(
        name="map_server", extension=".zip", media_type="application/zip", files=[".yaml", ".pgm"],
        options=["layer"],
        description="a grid layer (?layer=, default occupancy) as a ROS map_server YAML + PGM (served as a zip of "
                    "both)",
    )


@router.get("", summary="List export formats", responses={**not_found("No such map."), **UNPROCESSABLE})
def list_exports(map_info: MapDep) -> list[ExportFormatOut]:
    """The formats the map can be exported in, with the file each serves."""
    return [ExportFormatOut(name=item.name, description=item.description, extension=item.download[0],
                            media_type=item.download[1], files=list(item.files), options=sorted(item.options))
            for item in EXPORT_FORMATS.values()]


@router.get(
    "/{export_format}",
    summary="Export the map",
    response_class=Response,
    responses={
        status.HTTP_200_OK: {
            "content": {
                "application/geo+json": {"example": LAYOUT_EXAMPLE},
                "application/zip": {},
                "application/json": {"example": _LIF_EXAMPLE},
                "application/yaml": {"example": _RMF_EXAMPLE},
            },
            "description": "The export as a file to save (Content-Disposition names it): one-file formats as "
                           "that file, several files (map_server's YAML + PGM) as a zip.",
        },
        status.HTTP_404_NOT_FOUND: {"model": ErrorOut,
                                    "description": "No such map, revision, format or layer (the valid ones listed)."},
        status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut,
                                                "description": "An option the format does not take, or a layer "
                                                               "it cannot write."},
    },
)
def get_export(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    name: Annotated[str, Path(alias="export_format", max_length=64, examples=["map_server"],
                              description="Export format: `geojson`, `map_server`, `lif` or `rmf` "
                                          "(see `/exports`).")],
    layer: Annotated[str | None, Query(max_length=64, examples=["occupancy"],
                                       description="map_server only: the grid layer to export (default "
                                                   "`occupancy`); any layer of the map works.")] = None,
) -> Response:
    """The map as of `?revision=` (default: the newest) in a standard format.

    * `geojson`: every feature as one GeoJSON FeatureCollection (as `/layout`, unbounded).
    * `map_server`: a zip of `<name>.yaml` + `<name>.pgm`, a ROS map_server map of a grid layer:
      occupancy in `trinary` mode (free 254, occupied 0, unknown 205), label layers as their codes in
      `raw` mode, other layers scaled in `scale` mode with their value range in the YAML's `aisle` entry.
    * `lif`: the waypoint network as a VDMA LIF 1.0 layout (JSON): junctions and access points as nodes,
      corridors as edges, bins and docks as stations.
    * `rmf`: the same network as an Open-RMF nav graph (YAML).

    `lif` and `rmf` need the map decomposed into regions (404 until it is).
    """
    try:
        chosen = export_format(name)
        at = export_revision(store, map_info, revision)
        stem = export_stem(map_info, at, layer=(layer or DEFAULT_LAYER) if "layer" in chosen.options else None)
        export = export_map(store, map_info, chosen.name, revision=at, options=ExportOptions(stem, layer))
    except ExportNotFoundError as err:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(err)) from err
    except ExportError as err:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err)) from err
    extension, media_type = chosen.download
    if len(export.files) == 1:
        filename, content = next(iter(export.files.items()))
    else:
        filename, content = f"{stem}{extension}", zip_files(export.files)
    return Response(content, media_type=media_type,
                    headers={"Content-Disposition": f'attachment; filename="{filename}"', REVISION_HEADER: str(at)})
