"""The fast path and the routes make one access decision: for the same credentials they give the same answer
(status, detail, headers) in every case, charge each request once, and read keys as FastAPI reads them."""

from __future__ import annotations

import asyncio
import re
from collections.abc import Awaitable, Callable
from typing import Any

import httpx2
import pytest
from fastapi import FastAPI
from fastapi.security import APIKeyHeader, HTTPBearer
from fastapi.testclient import TestClient
from starlette.requests import Request

from api.access import Credentials, credentials_of
from api.fastpath import LiveReads
from shared.store import MapStore
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory

BIN = "/v1/maps/site/bins/B1"
MISSING_BIN = "/v1/maps/site/bins/NOPE"
AREA = "/v1/maps/site/features?bbox=0,0,3,3&kind=bin"
ROUTED = "x=1"
"""A query parameter no route reads: it sends a request past the fast path to FastAPI, and changes nothing else."""
STEADY = {"live_staleness_s": 3600.0, "key_recheck_s": 3600.0}
"""Keep the live state and verified keys in memory however slowly the test runs (nothing is written beside the
API, and a key revoked through it is forgotten at once), so the fast path answers all it may."""


def _routed(path: str) -> str:
    return f"{path}{'&' if '?' in path else '?'}{ROUTED}"


class RoutedCount:
    """Counts the requests the app's fast path hands on to FastAPI (wraps what :class:`LiveReads` calls)."""

    def __init__(self, client: TestClient) -> None:
        app = client.app
        assert isinstance(app, FastAPI)
        client.get("/v1/health")  # builds the middleware stack
        layer: Any = app.middleware_stack
        while not isinstance(layer, LiveReads):
            layer = layer.app
        self.count = 0
        inner: Callable[..., Awaitable[None]] = layer.app

        async def counting(scope: Any, receive: Any, send: Any) -> None:
            self.count += scope["type"] == "http"
            await inner(scope, receive, send)

        layer.app = counting


def _answer(response: httpx2.Response) -> tuple[int, Any, list[tuple[str, str]]]:
    """Status, body and headers, with the seconds a rate-limit refusal names (at least one) left out: time passes."""
    body = response.json()
    headers = sorted((name.lower(), value) for name, value in response.headers.multi_items())
    if response.status_code == 429:
        body = {"detail": re.sub(r"retry in \d+\.\d\d s", "retry in ... s", body["detail"])}
        assert int(response.headers["retry-after"]) >= 1
        headers = [(name, "..." if name == "retry-after" else value) for name, value in headers]
    return response.status_code, body, headers


@pytest.mark.parametrize("require_keys", [False, True])
def test_fast_and_routed_reads_answer_the_same_for_every_credential(
    store: MapStore, make_client: ClientFactory, site: dict[str, int], require_keys: bool
) -> None:
    secrets = {role: create_key(store, role=role, name=f"{role.value}-client")[1] for role in Role}
    revoked = create_key(store, role=Role.READ, name="leaver")[1]
    wrong = secrets[Role.READ][:-1] + ("A" if secrets[Role.READ][-1] != "A" else "B")
    client = make_client(store, require_keys_for_reads=require_keys, rate_limit_per_s=None, **STEADY)
    admin = {"X-API-Key": secrets[Role.ADMIN]}
    for path in (BIN, AREA):
        assert client.get(path, headers=admin).status_code == 200  # the map is found and its live state read
    assert client.get(BIN, headers={"X-API-Key": revoked}).status_code == 200  # verified, remembered ...
    assert client.delete(f"/v1/keys/{revoked.split('_')[1]}", headers=admin).status_code == 200  # ... revoked
    routed = RoutedCount(client)
    cases: list[tuple[str, dict[str, str], bool]] = [  # name, headers, decided from memory
        ("no key", {}, True),
        ("empty key", {"X-API-Key": ""}, True),
        ("malformed key", {"X-API-Key": "not-a-key"}, True),
        ("malformed bearer", {"Authorization": "Bearer ' OR 1=1 --"}, True),
        ("other scheme", {"Authorization": f"Basic {secrets[Role.READ]}"}, True),
        ("bearer without token", {"Authorization": "Bearer"}, True),
        ("unknown key", {"X-API-Key": "aisle_0123456789ab_" + "A" * 43}, False),
        ("wrong secret", {"X-API-Key": wrong}, False),
        ("revoked key", {"X-API-Key": revoked}, False),
        *((f"{role.value} key", {"X-API-Key": secret}, True) for role, secret in secrets.items()),
        ("read bearer", {"Authorization": f"bearer  {secrets[Role.READ]} "}, True),
        ("both headers", {"X-API-Key": secrets[Role.WRITE], "Authorization": "Bearer not-a-key"}, True),
    ]

    for name, headers, from_memory in cases:
        for path in (BIN, AREA, MISSING_BIN):
            by_route = client.get(_routed(path), headers=headers)  # first, so a good key is verified
            before = routed.count
            fast = client.get(path, headers=headers)
            fast_went_to_fastapi = routed.count > before

            assert _answer(fast) == _answer(by_route), (name, path)
            if path != MISSING_BIN:  # a missing bin is explained by the route, once let in
                assert fast_went_to_fastapi is not from_memory, (name, path)
    assert routed.count > 0


@pytest.mark.parametrize("require_keys", [False, True])
@pytest.mark.parametrize("keyed", [False, True])
def test_fast_and_routed_reads_are_rate_limited_alike(
    store: MapStore, make_client: ClientFactory, site: dict[str, int], require_keys: bool, keyed: bool
) -> None:
    admin = {"X-API-Key": create_key(store, role=Role.ADMIN, name="operator")[1]}
    headers = {"X-API-Key": create_key(store, role=Role.READ, name="wms")[1]} if keyed else {}
    answers = []
    for fast in (False, True):  # the same requests to two apps: one sends them through the fast path
        client = make_client(store, require_keys_for_reads=require_keys, rate_limit_per_s=0.001, rate_limit_burst=4,
                             **STEADY)
        assert client.get(BIN, headers=admin).status_code == 200  # the map is found and its live state read
        answers.append([_answer(client.get(BIN if fast else _routed(BIN), headers=headers)) for _ in range(5)])

    assert answers[0] == answers[1]
    assert answers[0][-1][0] == 429 and "retry-after" in dict(answers[0][-1][2])


@pytest.mark.parametrize("keyed", [False, True])
def test_a_read_the_fast_path_leaves_to_the_route_is_charged_once(
    store: MapStore, make_client: ClientFactory, site: dict[str, int], keyed: bool
) -> None:
    headers = {"X-API-Key": create_key(store, role=Role.READ, name="wms")[1]} if keyed else {}
    client = make_client(store, rate_limit_per_s=0.001, rate_limit_burst=5, **STEADY)
    routed = RoutedCount(client)  # its health probe takes one of the address's five requests, not the key's

    statuses = [client.get(MISSING_BIN, headers=headers).status_code for _ in range(6 if keyed else 5)]

    assert statuses == [404] * (len(statuses) - 1) + [429]
    assert routed.count == len(statuses)  # a missing bin is always left to the route, which charges it


_HEADER_SETS: list[list[tuple[bytes, bytes]]] = [
    [],
    [(b"x-api-key", b"k1")],
    [(b"x-api-key", b"")],
    [(b"x-api-key", b""), (b"authorization", b"Bearer t1")],
    [(b"x-api-key", b"k1"), (b"authorization", b"Bearer t1")],
    [(b"authorization", b"Bearer t1")],
    [(b"authorization", b"bEaReR  t1 ")],
    [(b"authorization", b"Bearer t1 t2")],
    [(b"authorization", b"Bearer")],
    [(b"authorization", b"Bearer ")],
    [(b"authorization", b" Bearer t1")],
    [(b"authorization", b"Basic t1")],
    [(b"authorization", b"")],
    [(b"x-api-key", b"k1"), (b"x-api-key", b"k2")],
    [(b"x-api-key", b""), (b"x-api-key", b"k2")],
    [(b"authorization", b"Basic t1"), (b"authorization", b"Bearer t2")],
    [(b"x-api-key", "clé".encode("latin-1"))],
    [(b"authorization", "Bearer clé".encode("latin-1"))],
]


@pytest.mark.parametrize("headers", _HEADER_SETS)
@pytest.mark.parametrize("client", [None, ("10.0.0.7", 5000)])
def test_credentials_are_read_as_fastapis_key_schemes_read_them(
    headers: list[tuple[bytes, bytes]], client: tuple[str, int] | None
) -> None:
    scope = {"type": "http", "method": "GET", "path": "/", "headers": headers, "query_string": b"", "client": client}
    request = Request(scope)

    async def by_fastapi() -> str | None:
        api_key = await APIKeyHeader(name="X-API-Key", auto_error=False)(request)
        bearer = await HTTPBearer(auto_error=False)(request)
        return api_key if api_key is not None else (None if bearer is None else bearer.credentials)

    assert credentials_of(scope) == Credentials(asyncio.run(by_fastapi()),
                                                request.client.host if request.client else "unknown")
