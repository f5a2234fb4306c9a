"""Conditional reads: an ``ETag`` on every successful ``GET`` answer, and ``304 Not Modified`` for a client that
already has it.

A read of the map at a revision gives the same bytes every time, so a WMS polling ``layout`` or a layer, or
re-reading a bin, sends ``If-None-Match`` with the tag it has and gets an empty 304 while nothing changed. The tag
is a hash of the answer as the route gives it (before any compression), so it is right for every read, at a
revision or live, whatever produced it; it is weak (``W/"…"``), as the bytes on the wire differ with the
encoding. Event streams (``text/event-stream``) pass untouched: they never end, and are never buffered.
"""

from __future__ import annotations

import hashlib
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

_DROPPED_ON_304 = frozenset({b"content-length", b"content-type", b"content-encoding", b"content-disposition"})


def etag_of(body: bytes) -> str:
    """The weak entity tag of an answer's body."""
    return f'W/"{hashlib.blake2b(body, digest_size=16).hexdigest()}"'


def matches(if_none_match: str, tag: str) -> bool:
    """Whether an ``If-None-Match`` header value names ``tag`` (weak comparison, RFC 9110 13.1.2) or is ``*``."""
    opaque = tag.removeprefix("W/")
    return any(item == "*" or item.removeprefix("W/") == opaque
               for item in (part.strip() for part in if_none_match.split(",")))


def _header(scope_or_message: Scope | Message, name: bytes) -> str | None:
    for key, value in scope_or_message["headers"]:
        if key.lower() == name:
            return bytes(value).decode("latin-1")
    return None


class ConditionalReads:
    """ASGI middleware: tags successful ``GET`` answers and answers a matching ``If-None-Match`` with 304."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "GET":
            await self.app(scope, receive, send)
            return
        if_none_match = _header(scope, b"if-none-match")
        start: Message | None = None
        passing = False
        chunks: list[bytes] = []

        async def tag(message: Message) -> None:
            nonlocal start, passing
            if passing:
                await send(message)
            elif message["type"] == "http.response.start":
                content_type = _header(message, b"content-type") or ""
                if message["status"] != 200 or content_type.startswith("text/event-stream"):
                    passing = True
                    await send(message)
                else:
                    start = message
            elif message["type"] == "http.response.body" and start is not None:
                chunks.append(message.get("body", b""))
                if not message.get("more_body", False):
                    await self._answer(start, b"".join(chunks), if_none_match, send)
            else:
                await send(message)

        await self.app(scope, receive, tag)

    @staticmethod
    async def _answer(start: Message, body: bytes, if_none_match: str | None, send: Send) -> None:
        etag = etag_of(body)
        headers = [*start["headers"], (b"etag", etag.encode("latin-1"))]
        if if_none_match is not None and matches(if_none_match, etag):
            headers = [(key, value) for key, value in headers if key.lower() not in _DROPPED_ON_304]
            await send({"type": "http.response.start", "status": 304, "headers": headers})
            await send({"type": "http.response.body", "body": b""})
            return
        await send({**start, "headers": headers})
        await send({"type": "http.response.body", "body": body})
