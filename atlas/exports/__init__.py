"""Standard exports of a map: a registry of formats, each an exporter that turns the map into files.

An exporter is ``exporter(store, map_info, revision, options) -> Export`` (:data:`Exporter`): the
map as of revision id ``revision`` as files ``{filename: bytes}``, main file first, plus the main
file's media type. The REST API serves a one-file export as that file and several files as a zip;
``aisle export`` writes them to disk.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from atlas.exports.base import Export, Exporter, ExportError, ExportNotFoundError, ExportOptions, safe_stem
from atlas.exports.geojson import export_geojson
from atlas.exports.lif import MEDIA_TYPE as LIF_MEDIA_TYPE
from atlas.exports.lif import export_lif
from atlas.exports.mapserver import MEDIA_TYPE as MAP_SERVER_MEDIA_TYPE
from atlas.exports.mapserver import export_map_server
from atlas.exports.rmf import MEDIA_TYPE as RMF_MEDIA_TYPE
from atlas.exports.rmf import export_rmf
from atlas.layout import MEDIA_TYPE as GEOJSON_MEDIA_TYPE
from shared.store import MapInfo, MapStore


@dataclass(frozen=True, slots=True)
class ExportFormat:
    """A registered export format.

    Parameters
    ----------
    name : str
        What clients ask for (``geojson``, ``map_server``, ...).
    description : str
        One line for people.
    files : tuple of str
        Extensions of the files it makes (with their dots), the main file first.
    media_type : str
        Media type of the main file.
    exporter : Exporter
        Makes the export.
    options : frozenset of str
        :class:`ExportOptions` fields the format uses besides ``stem`` (e.g. ``layer``).
    """

    name: str
    description: str
    files: tuple[str, ...]
    media_type: str
    exporter: Exporter
    options: frozenset[str] = frozenset()

    @property
    def extension(self) -> str:
        """Extension of the main file, with its dot (``aisle export --out`` names it)."""
        return self.files[0]

    @property
    def download(self) -> tuple[str, str]:
        """(extension, media type) of what the API serves: the one file itself, or a zip of several."""
        return (self.extension, self.media_type) if len(self.files) == 1 else (".zip", ZIP_MEDIA_TYPE)


ZIP_MEDIA_TYPE = "application/zip"
"""How the API serves an export of several files."""

EXPORT_FORMATS: Mapping[str, ExportFormat] = {
    item.name: item for item in (
        ExportFormat("geojson", "every feature of the map as one GeoJSON FeatureCollection (map-frame metres)",
                     (".geojson",), GEOJSON_MEDIA_TYPE, export_geojson),
        ExportFormat("map_server", "a grid layer (?layer=, default occupancy) as a ROS map_server YAML + PGM "
                     "(served as a zip of both)", (".yaml", ".pgm"), MAP_SERVER_MEDIA_TYPE, export_map_server,
                     frozenset({"layer"})),
        ExportFormat("lif", "the waypoint network as a VDMA LIF 1.0 layout (nodes, edges, stations), JSON",
                     (".lif.json",), LIF_MEDIA_TYPE, export_lif),
        ExportFormat("rmf", "the waypoint network as an Open-RMF nav graph, YAML", (".nav.yaml",), RMF_MEDIA_TYPE,
                     export_rmf),
    )
}
"""Every format, by name."""


def export_format(name: str) -> ExportFormat:
    """The format called ``name``, or :class:`ExportNotFoundError` listing the known ones."""
    found = EXPORT_FORMATS.get(name)
    if found is None:
        raise ExportNotFoundError(f"unknown export format {name!r}; known formats: {sorted(EXPORT_FORMATS)}")
    return found


def export_revision(store: MapStore, map_info: MapInfo, revision: int | None) -> int:
    """The revision id an export reads: ``revision`` after checking it is the map's, else the newest.

    Raises
    ------
    ExportNotFoundError
        ``revision`` is not a revision of the map, or the map has no revisions yet.
    """
    latest = store.latest_revision(map_info.id)
    if latest is None:
        raise ExportNotFoundError(f"map {map_info.name!r} has no revisions yet; there is nothing to export")
    if revision is None:
        return latest.id
    found = store.revisions(map_info.id, after_id=revision - 1, limit=1) if revision >= 1 else []
    if not found or found[0].id != revision:
        raise ExportNotFoundError(f"revision {revision} is not a revision of map {map_info.name!r}; "
                                  f"its newest is {latest.id}")
    return revision


def export_stem(map_info: MapInfo, revision: int, *, layer: str | None = None) -> str:
    """Default file stem of an export: ``<map>_r<revision>``, or ``<map>_<layer>_r<revision>``."""
    parts = [map_info.name] + ([layer] if layer else []) + [f"r{revision}"]
    return safe_stem("_".join(parts))


def export_map(store: MapStore, map_info: MapInfo, format_name: str, *, revision: int,
               options: ExportOptions) -> Export:
    """Export the map as of ``revision`` (from :func:`export_revision`) in format ``format_name``.

    Raises
    ------
    ExportNotFoundError
        Unknown format, or something the format needs does not exist (e.g. the layer).
    ExportError
        An option the format does not take, or a map the format cannot express.
    """
    chosen = export_format(format_name)
    if options.layer is not None and "layer" not in chosen.options:
        raise ExportError(f"format {chosen.name!r} exports no grid layer; leave out the layer option")
    return chosen.exporter(store, map_info, revision, options)


def zip_files(files: Mapping[str, bytes]) -> bytes:
    """A zip archive (deflated) holding ``files`` by name."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, content in files.items():
            archive.writestr(name, content)
    return buffer.getvalue()


def export_to_path(store: MapStore, map_info: MapInfo, format_name: str, out: Path, *, revision: int | None,
                   layer: str | None = None) -> list[Path]:
    """Write an export to ``out``; the paths written, main file first.

    A one-file export is written to ``out`` itself. The files of a several-file export go beside
    each other in ``out``'s folder, named after ``out`` without the format's extension: for
    map_server, ``--out maps/site`` and ``--out maps/site.yaml`` both write ``maps/site.yaml`` and
    ``maps/site.pgm``.
    """
    chosen = export_format(format_name)
    at = export_revision(store, map_info, revision)
    stem = out.name[: -len(chosen.extension)] if out.name.endswith(chosen.extension) else out.name
    export = export_map(store, map_info, chosen.name, revision=at, options=ExportOptions(safe_stem(stem), layer))
    out.parent.mkdir(parents=True, exist_ok=True)
    if len(export.files) == 1:
        out.write_bytes(next(iter(export.files.values())))
        return [out]
    written = [out.parent / name for name in export.files]
    for path, content in zip(written, export.files.values(), strict=True):
        path.write_bytes(content)
    return written


__all__ = [
    "EXPORT_FORMATS",
    "ZIP_MEDIA_TYPE",
    "Export",
    "ExportError",
    "ExportFormat",
    "ExportNotFoundError",
    "ExportOptions",
    "Exporter",
    "export_format",
    "export_map",
    "export_revision",
    "export_stem",
    "export_to_path",
    "safe_stem",
    "zip_files",
]
