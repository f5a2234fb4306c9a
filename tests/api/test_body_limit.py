"""The request body limit (``AISLE_API_MAX_BODY_BYTES``): a 413 with a JSON detail, sent before a body over the
limit is read whole (whether its size is declared or it comes chunked), and errors never echo a large body.

Through a real uvicorn server on loopback, with raw sockets, so the test controls how much of a body is sent.
"""

from __future__ import annotations

import http.client
import json
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest

from api import create_app
from shared.settings import Settings
from shared.store import MapStore
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory, served

LIMIT = 256 * 1024
PATH = "/v1/maps/site/wms-bins"


@pytest.fixture
def writer(store: MapStore) -> str:
    return create_key(store, role=Role.WRITE, name="wms")[1]


def _serve(store: MapStore, tmp_path: Path, *, max_body_bytes: int) -> Iterator[int]:
    app = create_app(store=store, settings=Settings(data_dir=tmp_path, database_url=store.url,
                                                    api_max_body_bytes=max_body_bytes))
    with served(app) as port:
        yield port


@pytest.fixture
def port(store: MapStore, tmp_path: Path, site: dict[str, int]) -> Iterator[int]:
    """The API with a body limit of ``LIMIT`` bytes."""
    yield from _serve(store, tmp_path, max_body_bytes=LIMIT)


def _newest(store: MapStore) -> int | None:
    latest = store.latest_revision(store.ensure_map("site").id)
    return None if latest is None else latest.id


def _answer(sock: socket.socket) -> tuple[int, bytes]:
    response = http.client.HTTPResponse(sock)
    response.begin()
    return response.status, response.read()


def _head(key: str, *framing: str) -> bytes:
    lines = [f"PUT {PATH} HTTP/1.1", "Host: 127.0.0.1", "Content-Type: application/json", f"X-API-Key: {key}",
             *framing]
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def test_a_declared_size_over_the_limit_is_a_413_before_the_body_is_sent(
    store: MapStore, port: int, writer: str, site: dict[str, int]
) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(_head(writer, f"Content-Length: {100 * LIMIT}") + b'{"bins": [')  # and nothing more
        status, body = _answer(sock)

    assert status == 413
    detail = json.loads(body)["detail"]
    assert str(LIMIT) in detail and "AISLE_API_MAX_BODY_BYTES" in detail
    assert _newest(store) == site["semantics_2"]


def test_a_chunked_body_is_refused_as_soon_as_it_passes_the_limit(
    store: MapStore, port: int, writer: str, site: dict[str, int]
) -> None:
    chunk = b"[" + b" " * (64 * 1024 - 1)  # the body would be invalid JSON: only the limit may answer
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(_head(writer, "Transfer-Encoding: chunked"))
        for _ in range(LIMIT // len(chunk) + 1):  # just over the limit, and the body never ends
            sock.sendall(f"{len(chunk):x}\r\n".encode() + chunk + b"\r\n")
        status, body = _answer(sock)

    assert status == 413
    assert "AISLE_API_MAX_BODY_BYTES" in json.loads(body)["detail"]
    assert _newest(store) == site["semantics_2"]


FIFTY_MB = 50 * 10**6


def _fifty_mb_wms_list() -> bytes:
    """A 50 MB WMS list whose one bin id is 50 MB of text (invalid: ids are short)."""
    return json.dumps({"bins": [{"id": "x" * FIFTY_MB}]}).encode()


def test_a_50_mb_body_over_the_default_limit_is_a_short_413(
    store: MapStore, make_client: ClientFactory, writer: str, site: dict[str, int]
) -> None:
    response = make_client(store).put(PATH, content=_fifty_mb_wms_list(),
                                      headers={"Content-Type": "application/json", "X-API-Key": writer})

    assert response.status_code == 413
    assert len(response.content) < 2000
    assert f"{32 * 2**20} bytes" in response.json()["detail"]
    assert _newest(store) == site["semantics_2"]


def test_a_50_mb_body_under_a_raised_limit_gets_a_422_that_does_not_echo_it(
    store: MapStore, tmp_path: Path, writer: str, site: dict[str, int]
) -> None:
    for port in _serve(store, tmp_path, max_body_bytes=64 * 2**20):
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
        try:
            connection.request("PUT", PATH, body=_fifty_mb_wms_list(),
                               headers={"Content-Type": "application/json", "X-API-Key": writer})
            response = connection.getresponse()
            status, body = response.status, response.read()
        finally:
            connection.close()

    assert status == 422
    assert len(body) < 2000
    assert json.loads(body)["detail"]
    assert _newest(store) == site["semantics_2"]
