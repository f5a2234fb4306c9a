"""The request body limit: a body over ``max_bytes`` is answered 413 with a JSON ``detail``, before it is read whole.

A declared ``Content-Length`` over the limit is refused before the app runs; a chunked body (or one longer than it
declared) is counted as it is read, and refused as soon as it passes the limit. Starlette's own ``max_body_size``
answers a declared size over the limit in plain text whatever the app sends, hence this small middleware.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from fastapi import HTTPException, status
from starlette.datastructures import Headers
from starlette.responses import JSONResponse

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


class BodyTooLargeError(HTTPException):
    """A 413 raised while a body over the limit is read (FastAPI answers it as any HTTPException)."""

    def __init__(self, max_bytes: int) -> None:
        super().__init__(status.HTTP_413_CONTENT_TOO_LARGE,
                         f"request body larger than the {max_bytes} bytes this API reads ({max_bytes / 2**20:.1f} "
                         "MiB, set by AISLE_API_MAX_BODY_BYTES); send less at once")


class BodyLimit:
    """ASGI middleware refusing request bodies over ``max_bytes`` with a 413 (see the module docstring).

    Parameters
    ----------
    app : ASGI app
        What answers the requests.
    max_bytes : int
        Largest body read, bytes.
    """

    def __init__(self, app: ASGIApp, *, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = Headers(scope=scope).get("content-length", "")
        if declared.isdigit() and int(declared) > self.max_bytes:
            await self._refuse(scope, receive, send)
            return
        received = 0
        started = False

        async def counted_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    raise BodyTooLargeError(self.max_bytes)
            return message

        async def watched_send(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted_receive, watched_send)
        except BodyTooLargeError:  # read outside a route (FastAPI answers those raised inside one)
            if started:
                raise
            await self._refuse(scope, receive, send)

    async def _refuse(self, scope: Scope, receive: Receive, send: Send) -> None:
        refusal = BodyTooLargeError(self.max_bytes)
        response = JSONResponse({"detail": refusal.detail}, status_code=refusal.status_code,
                                headers={"Connection": "close"})
        await response(scope, receive, send)
