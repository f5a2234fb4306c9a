"""The two hottest reads of a WMS, answered straight from memory: one bin by id, and live features by area.

FastAPI's routing and dependency handling cost several times what answering these from the live state does
(:mod:`atlas.live`), so :class:`LiveReads` answers them before FastAPI when nothing needs more: a plain ``GET`` of
``/v1/maps/{map}/bins/{id}`` or ``/v1/maps/{map}/features`` with only ``bbox``, ``kind``, ``limit`` and
``offset``, all valid; a map already found, whose live state is fresh; no key where none is needed, or a key
verified recently (:meth:`api.access.AccessPolicy.remembered`) with the role needed, within its rate limit.
It uses the routes' own checks and encoders, so the answer is the one the route gives. Any other request,
and any that would be refused, goes to FastAPI unchanged, which answers it (or explains the refusal) as always.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import parse_qsl

from fastapi import HTTPException
from fastapi.security.utils import get_authorization_scheme_param

from api.access import API_KEY_HEADER, required_role
from api.answers import live_bin
from api.deps import ApiContext
from api.queries import BIN_ID_REGEX, DEFAULT_LIMIT, MAX_BBOX_TEXT, MAX_LIMIT, MAX_OFFSET, bbox_of, check_kinds
from atlas.features import live_collection
from shared.vocabulary import REVISION_HEADER

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

BIN_ROUTE = "/v1/maps/{map_name}/bins/{bin_id}"
FEATURES_ROUTE = "/v1/maps/{map_name}/features"
_KEY_HEADER = API_KEY_HEADER.lower().encode("latin-1")


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
            return
        body, revision_id = answer
        await send({"type": "http.response.start", "status": 200, "headers": [
            (b"content-length", str(len(body)).encode()), (b"content-type", b"application/json"),
            (REVISION_HEADER.lower().encode(), str(revision_id).encode())]})
        await send({"type": "http.response.body", "body": body})

    def _answer(self, scope: Scope) -> tuple[bytes, int] | None:
        """The JSON answer and the revision it covers, or None to leave the request to FastAPI."""
        parts = scope["path"].split("/")
        if scope.get("root_path") or len(parts) not in (5, 6) or parts[:3] != ["", "v1", "maps"]:
            return None
        map_info = self.context.maps.get(parts[3])
        if map_info is None:
            return None
        query = parse_qsl(scope["query_string"].decode("latin-1"), keep_blank_values=True)
        if len(parts) == 6 and parts[4] == "bins" and not query and BIN_ID_REGEX.fullmatch(parts[5]):
            route = BIN_ROUTE
        elif len(parts) == 5 and parts[4] == "features":
            route = FEATURES_ROUTE
        else:
            return None
        live = self.context.live.peek(map_info)
        if live is None or not self._let_in(scope, route):
            return None
        try:
            if route == BIN_ROUTE:
                return live_bin(live, map_info, parts[5]), live.revision_id
            area = _area_query(query)
            if area is None:
                return None
            kinds, bbox, limit, offset = area
            return live_collection(live.features, kinds=kinds, bbox=bbox, limit=limit, offset=offset), \
                live.revision_id
        except HTTPException:  # a 404 or 422: the route explains it
            return None

    def _let_in(self, scope: Scope, route: str) -> bool:
        """Whether the caller may read ``route`` with what is known in memory; charges their rate limit if so."""
        access = self.context.access
        api_key = bearer = None
        for name, value in scope["headers"]:
            if name == _KEY_HEADER and api_key is None:
                api_key = value.decode("latin-1")
            elif name == b"authorization" and bearer is None:
                scheme, credentials = get_authorization_scheme_param(value.decode("latin-1"))
                bearer = credentials if scheme.lower() == "bearer" and credentials else ""
        secret = api_key or bearer or None
        required = required_role("GET", route, require_keys_for_reads=access.require_keys_for_reads)
        if secret is None:
            if required is not None:
                return False
            client = scope.get("client")
            bucket = f"address:{client[0] if client else 'unknown'}"
        else:
            key = access.remembered(secret)
            if key is None or (required is not None and not key.role.covers(required)):
                return False
            bucket = f"key:{key.key_id}"
        try:
            access.charge(bucket)
        except HTTPException:  # over the limit: the route refuses with 429 and Retry-After
            return False
        return True


def _area_query(query: list[tuple[str, str]]) -> tuple[list[str] | None, tuple[float, float, float, float] | None,
                                                       int, int] | None:
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
