"""Query and path parameters several routers share: the ``?bbox=`` box, ``?kind=`` feature kinds, bin ids and
paging limits, each parsed once with the 422 that says what is wrong."""

from __future__ import annotations

import base64
import math
import re
from collections.abc import Callable
from typing import Annotated, NamedTuple

from fastapi import Depends, HTTPException, Query, status

from api.deps import MAX_ID
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


class Cursor(NamedTuple):
    """Where the next page of a list starts: the revision the first page was read at, and the items to skip."""

    revision: int
    offset: int

    def encode(self) -> str:
        """The cursor as the opaque text a client passes back as ``?cursor=``."""
        return base64.urlsafe_b64encode(f"{_CURSOR_VERSION}:{self.revision}:{self.offset}".encode()).decode()


_CURSOR_VERSION = "c1"
_CURSOR_TEXT = 64


def cursors_at(revision: int) -> Callable[[int], str]:
    """The cursor of the page that starts at a given offset, read at ``revision``."""
    return lambda offset: Cursor(revision, offset).encode()


def next_cursor(revision: int | None, offset: int, *, more: bool) -> str | None:
    """The cursor of the page after one ending at ``offset`` read at ``revision``; None on the last page (or when
    there is no revision to page at: the map has none)."""
    return Cursor(revision, offset).encode() if more and revision is not None else None


def cursor_of(text: str) -> Cursor:
    """The cursor ``text`` (a ``next_cursor`` of an earlier page), or 422 saying it is not one."""
    try:
        version, revision, offset = base64.urlsafe_b64decode(text.encode("ascii")).decode("ascii").split(":")
        cursor = Cursor(int(revision), int(offset))
    except (ValueError, UnicodeError):  # base64's errors are ValueErrors
        version, cursor = "", None
    if cursor is None or version != _CURSOR_VERSION or not (1 <= cursor.revision <= MAX_ID
                                                             and 0 <= cursor.offset <= MAX_OFFSET):
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                            f"cursor {text[:_CURSOR_TEXT]!r} is not one this API gave; pass a page's `next_cursor` "
                            "as it is, or leave it out for the first page")
    return cursor


async def get_cursor(
    cursor: Annotated[str | None, Query(
        max_length=_CURSOR_TEXT, examples=["YzE6MTIwNzoyMDA="],
        description="The `next_cursor` of the previous page: the next page, read at the same revision as the first "
                    "(pages stay consistent while new revisions arrive). Leave out `revision` and `offset` with it."),
    ] = None,
) -> Cursor | None:
    return None if cursor is None else cursor_of(cursor)


CursorQuery = Annotated[Cursor | None, Depends(get_cursor)]


def page_start(cursor: Cursor | None, revision: int | None, offset: int) -> tuple[int | None, int]:
    """The revision and offset to read a page at: the cursor's, or else ``?revision=`` and ``?offset=``.

    A cursor with a ``revision`` or a non-zero ``offset`` is a 422: the cursor already says both.
    """
    if cursor is None:
        return revision, offset
    if revision is not None or offset:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                            "pass either cursor (for the next page) or revision and offset, not both")
    return cursor.revision, cursor.offset
