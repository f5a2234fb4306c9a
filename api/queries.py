"""Query and path parameters several routers share: the ``?bbox=`` box, ``?kind=`` feature kinds, bin ids and
paging limits, each parsed once with the 422 that says what is wrong."""

from __future__ import annotations

import math
import re
from typing import Annotated

from fastapi import Depends, HTTPException, Query, status

from atlas.features import BBox
from shared.store import FEATURE_KINDS

MAX_BBOX_SIDE_M = 100_000.0
"""Longest accepted bbox side; a warehouse is far smaller, so anything larger is a mistake."""
MAX_BBOX_TEXT = 200
"""Longest accepted ``?bbox=`` text, characters."""
MAX_LIMIT = 10_000
"""Largest page of features (``?limit=``)."""
DEFAULT_LIMIT = 1000
MAX_OFFSET = 10_000_000
"""Largest ``?offset=``; a map has far fewer features."""

BIN_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:-]{0,127}$"
"""What a bin id may look like: a WMS's own, or Aisle's (:data:`shared.bins.ID_FORMAT`)."""
BIN_ID_REGEX = re.compile(BIN_ID_PATTERN)


def check_kinds(kinds: list[str]) -> list[str]:
    """``kinds`` if each is a feature kind, else 422 naming the valid ones."""
    unknown = sorted(set(kinds) - FEATURE_KINDS)
    if unknown:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"unknown feature kind(s) {unknown}; valid kinds: {sorted(FEATURE_KINDS)}",
        )
    return kinds


async def get_kinds(
    kind: Annotated[
        list[str] | None,
        Query(description="Only features of these kinds (repeatable). One of: "
                          f"{', '.join(sorted(FEATURE_KINDS))}.", examples=[["bin", "rack_row"]]),
    ] = None,
) -> list[str] | None:
    return None if kind is None else check_kinds(kind)


async def parse_bbox(
    bbox: Annotated[
        str | None,
        Query(description="`minx,miny,maxx,maxy` in map-frame metres: only features whose bounds touch it.",
              examples=["0,0,25.5,40"], max_length=MAX_BBOX_TEXT),
    ] = None,
) -> BBox | None:
    """The ``?bbox=`` box, or 422 saying what is wrong with it."""
    return None if bbox is None else bbox_of(bbox)


def bbox_of(text: str) -> BBox:
    """The box ``minx,miny,maxx,maxy`` (metres) of a ``?bbox=``, or 422 saying what is wrong with it."""
    parts = text.split(",")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox must be four finite numbers minx,miny,maxx,maxy in metres, not {text!r}",
        )
    min_x, min_y, max_x, max_y = values
    if min_x > max_x or min_y > max_y:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox {text!r} has min greater than max; order is minx,miny,maxx,maxy",
        )
    if max_x - min_x > MAX_BBOX_SIDE_M or max_y - min_y > MAX_BBOX_SIDE_M:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox {text!r} is more than {MAX_BBOX_SIDE_M:.0f} m on a side; "
            "coordinates are metres in the map frame",
        )
    return min_x, min_y, max_x, max_y


KindsQuery = Annotated[list[str] | None, Depends(get_kinds)]
BBoxQuery = Annotated[BBox | None, Depends(parse_bbox)]
