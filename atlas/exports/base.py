"""What every exporter takes and gives, and the errors it raises."""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from shared.store import MapInfo, MapStore


class ExportError(ValueError):
    """An export that cannot be made as asked (a layer that cannot be written in the format, ...)."""


class ExportNotFoundError(ExportError):
    """An export of something that does not exist: an unknown format, map, revision or layer."""


_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def safe_stem(text: str) -> str:
    """``text`` as a file-name stem: letters, digits, ``.``, ``_`` and ``-`` kept, runs of anything else ``_``.

    Examples
    --------
    >>> safe_stem('dc "east"/2')
    'dc_east_2'
    """
    return _UNSAFE.sub("_", text).strip("_.") or "map"


@dataclass(frozen=True, slots=True)
class ExportOptions:
    """How to make an export.

    Parameters
    ----------
    stem : str
        File-name stem of the files written (a format with several files names them ``<stem>.<ext>``
        and refers to them by those names, as map_server's YAML names its image).
    layer : str, optional
        Grid layer to export, for formats that write one (map_server); None: the format's default.
    """

    stem: str
    layer: str | None = None

    def __post_init__(self) -> None:
        if not self.stem or safe_stem(self.stem) != self.stem:
            raise ExportError(f"file stem {self.stem!r} must be non-empty and use only letters, digits, '.', '_', '-'")


@dataclass(frozen=True, slots=True)
class Export:
    """An export: its files (name -> content, main file first) and the media type of the main file."""

    files: Mapping[str, bytes]
    media_type: str

    def __post_init__(self) -> None:
        if not self.files:
            raise ExportError("an export needs at least one file")


Exporter = Callable[[MapStore, MapInfo, int, ExportOptions], Export]
"""``exporter(store, map_info, revision, options)``: the map as it was at revision id ``revision``."""
