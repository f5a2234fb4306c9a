"""The two hottest reads of a WMS, answered straight from memory: one bin by id, and live features by area.

FastAPI's routing and dependency handling cost several times what answering these from the live state does
(:mod:`atlas.live`), so :class:`LiveReads` answers them before FastAPI when nothing needs more: a plain ``GET`` of
``/v1/maps/{map}/bins/{id}`` or ``/v1/maps/{map}/features`` with only ``bbox``, ``kind``, ``limit`` and
``offset``, all valid, of a map already found; an access decision that memory suffices for
(:meth:`api.access.AccessPolicy.judge`, the in-memory part of :meth:`~api.access.AccessPolicy.admit`, the one
decision the routes make too); and, unless that decision is a refusal (401, 403, 429: answered as FastAPI answers
it), a fresh live state. It uses the routes' own checks and encoders, so every answer is the one the route gives.
Any other request goes to FastAPI unchanged and uncharged, which answers it (or explains the refusal) as always.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import parse_qsl

from fastapi import HTTPException
from fastapi.exception_handlers import http_exception_handler
from starlette.requests import Request

from api.access import AccessPolicy, Verdict, credentials_of
from api.answers import live_bin
from api.deps import ApiContext
from api.queries import (
    BIN_ID_REGEX,
    DEFAULT_LIMIT,
    MAX_BBOX_TEXT,
    MAX_LIMIT,
    MAX_OFFSET,
    bbox_of,
    check_kinds,
    cursors_at,
)
from atlas.features import live_collection
from shared.vocabulary import REVISION_HEADER

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

_Area = tuple[list[str] | None, tuple[float, float, float, float] | None, int, int]
"""A features query: kinds (None: all), bbox (None: everywhere), limit, offset."""

BIN_ROUTE = "/v1/maps/{map_name}/bins/{bin_id}"
FEATURES_ROUTE = "/v1/maps/{map_name}/features"


class LiveReads:
    """ASGI middleware answering live bin and feature-area reads from memory (see the module docstring).

    Parameters
    ----------
    app : ASGI app
        What answers every other request (the FastAPI app's inner stack).
    context : ApiContext
        The app's context: its maps, live state and access policy.
    """

    def __init__(self, app: ASGIApp, context: ApiContext) -> None:
        self.app = app
        self.context = context

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        answer = self._answer(scope) if scope["type"] == "http" and scope["method"] == "GET" else None
        if answer is None:
            await self.app(scope, receive, send)
        elif isinstance(answer, HTTPException):  # as FastAPI answers a refusal raised by a dependency
            await (await http_exception_handler(Request(scope), answer))(scope, receive, send)
        else:
            body, revision_id = answer
            await send({"type": "http.response.start", "status": 200, "headers": [
                (b"content-length", str(len(body)).encode()), (b"content-type", b"application/json"),
                (REVISION_HEADER.lower().encode(), str(revision_id).encode())]})
            await send({"type": "http.response.body", "body": body})

    def _answer(self, scope: Scope) -> tuple[bytes, int] | HTTPException | None:
        """The JSON answer and the revision it covers, the access refusal, or None to leave the request to FastAPI.

        Charges the caller's rate limit when it answers, never when it leaves the request to FastAPI (which does).
        """
        parts = scope["path"].split("/")
        if scope.get("root_path") or len(parts) not in (5, 6) or parts[:3] != ["", "v1", "maps"]:
            return None
        map_info = self.context.maps.get(parts[3])
        if map_info is None:
            return None
        raw_query = scope["query_string"]  # most bin reads have none, and parsing nothing costs 1.5 us
        query = parse_qsl(raw_query.decode("latin-1"), keep_blank_values=True) if raw_query else []
        if len(parts) == 6 and parts[4] == "bins" and not query and BIN_ID_REGEX.fullmatch(parts[5]):
            route, area = BIN_ROUTE, None
        elif len(parts) == 5 and parts[4] == "features":
            route = FEATURES_ROUTE
            try:
                area = _area_query(query)
            except HTTPException:  # a 422: the route explains it, after the access decision
                return None
            if area is None:
                return None
        else:
            return None
        access = self.context.access
        verdict = access.judge(credentials_of(scope), method="GET", route=route)
        if verdict is None:  # the key's row must be read: the route does it in a worker thread
            return None
        if verdict.refusal is not None:
            return _settle(access, verdict)
        live = self.context.live.peek(map_info)
        if live is None:
            return None
        try:
            body = (live_bin(live, map_info, parts[5]) if area is None
                    else live_collection(live.features, kinds=area[0], bbox=area[1], limit=area[2], offset=area[3],
                                         next_cursor=cursors_at(live.revision_id)))
        except HTTPException:  # a 404: the route explains it
            return None
        return _settle(access, verdict) or (body, live.revision_id)


def _settle(access: AccessPolicy, verdict: Verdict) -> HTTPException | None:
    """Carry out ``verdict`` (charge the caller's rate limit): the refusal to answer, or None to let them in."""
    try:
        access.settle(verdict)
    except HTTPException as refusal:
        return refusal
    return None


def _area_query(query: list[tuple[str, str]]) -> _Area | None:
    """(kinds, bbox, limit, offset) of a features query, or None unless it is plainly valid and has only those.

    Raises the route's 422 for a bad bbox or kind.
    """
    kinds: list[str] = []
    single: dict[str, str] = {}
    for name, value in query:
        if name == "kind":
            kinds.append(value)
        elif name in ("bbox", "limit", "offset") and name not in single:
            single[name] = value
        else:
            return None
    bbox_text = single.get("bbox")
    if bbox_text is not None and len(bbox_text) > MAX_BBOX_TEXT:
        return None
    limit = _digits(single.get("limit", str(DEFAULT_LIMIT)), 1, MAX_LIMIT)
    offset = _digits(single.get("offset", "0"), 0, MAX_OFFSET)
    if limit is None or offset is None:
        return None
    return (check_kinds(kinds) if kinds else None), (None if bbox_text is None else bbox_of(bbox_text)), limit, offset


def _digits(text: str, low: int, high: int) -> int | None:
    """``text`` as an int if it is plain decimal digits within [low, high], else None."""
    if not (text.isascii() and text.isdigit() and len(text) <= 12):
        return None
    value = int(text)
    return value if low <= value <= high else None
