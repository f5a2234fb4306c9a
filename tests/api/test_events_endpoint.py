"""/v1/maps/{map}/events: each revision once, in order, resumable with Last-Event-ID; heartbeats; clean close."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import numpy as np
import pytest
from fastapi.testclient import TestClient

from api.deps import ApiContext
from shared.store import GridLayer, MapStore, RevisionWrite
from tests.api.conftest import ClientFactory
from tests.helpers import wait_for

URL = "/v1/maps/site/events"
FAST = {"event_poll_s": 0.02, "event_heartbeat_s": 0.1}


class Event(NamedTuple):
    id: int
    name: str | None
    data: dict[str, Any]


def _read(lines: Iterator[str], count: int, *, timeout_s: float = 10.0) -> tuple[list[Event], list[str]]:
    """The next ``count`` events of an SSE line stream, and the comments seen on the way."""
    deadline = time.monotonic() + timeout_s
    events: list[Event] = []
    comments: list[str] = []
    fields: dict[str, str] = {}
    while len(events) < count:
        if time.monotonic() > deadline:
            pytest.fail(f"only {len(events)} of {count} events within {timeout_s} s")
        line = next(lines)
        if line.startswith(":"):
            comments.append(line[1:].strip())
        elif line:
            name, _, value = line.partition(":")
            fields[name] = value.removeprefix(" ")
        else:
            if "data" in fields:
                events.append(Event(int(fields["id"]), fields.get("event"), json.loads(fields["data"])))
            fields = {}
    return events, comments


def _write(store: MapStore, map_name: str, n: int) -> list[int]:
    map_id = store.ensure_map(map_name).id
    layer = GridLayer("occupancy", np.zeros((2, 2), dtype=np.int8), 0.5, 0.0, 0.0)
    return [store.write_revision(map_id, RevisionWrite("occupancy_mapping", layers=[layer])).id for _ in range(n)]


def _context(client: TestClient) -> ApiContext:
    context = client.app.state.context  # type: ignore[attr-defined]
    assert isinstance(context, ApiContext)
    return context


def test_reconnecting_with_last_event_id_gets_every_later_revision_once_in_order(
    store: MapStore, make_client: ClientFactory
) -> None:
    client = make_client(store, **FAST)
    written = _write(store, "site", 5)
    _write(store, "other", 2)  # another map's revisions never show up
    received: list[int] = []

    with client.stream("GET", URL, params={"after": 0}) as response:
        assert response.headers["content-type"].startswith("text/event-stream")
        events, _ = _read(response.iter_lines(), 3)
        received += [event.id for event in events]
    written += _write(store, "site", 2)  # while disconnected
    with client.stream("GET", URL, params={"after": 0}, headers={"Last-Event-ID": str(received[-1])}) as response:
        lines = response.iter_lines()
        events, _ = _read(lines, 4)
        received += [event.id for event in events]
        written += _write(store, "site", 3)  # while connected
        events, _ = _read(lines, 3)
        received += [event.id for event in events]

    assert received == written
    assert all(event.name == "revision" for event in events)


def test_event_data_summarises_the_revision(store: MapStore, make_client: ClientFactory,
                                            site: dict[str, int]) -> None:
    with make_client(store, **FAST).stream("GET", URL, params={"after": site["occupancy_1"]}) as response:
        events, comments = _read(response.iter_lines(), 3)

    assert [event.id for event in events] == [site["semantics_1"], site["occupancy_2"], site["semantics_2"]]
    first = events[0].data
    assert first["revision_id"] == site["semantics_1"] and first["map"] == "site" and first["stage"] == "semantics"
    assert first["layers_updated"] == ["traversability"]
    assert first["features"]["bin"] == {"added": 2, "removed": 0, "moved": 0, "changed": 0, "total": 2}
    assert first["topology_changed"] is False and first["created_at"]
    assert events[2].data["features"] == {"bin": {"added": 0, "removed": 1, "moved": 1, "changed": 0, "total": 1}}
    assert any(f"revisions after {site['occupancy_1']}" in comment for comment in comments)


def test_without_a_cursor_the_stream_starts_at_the_newest_revision(
    store: MapStore, make_client: ClientFactory, site: dict[str, int]
) -> None:
    with make_client(store, **FAST).stream("GET", URL) as response:
        lines = response.iter_lines()
        newer = _write(store, "site", 1)
        events, _ = _read(lines, 1)

    assert [event.id for event in events] == newer
    assert newer[0] > site["semantics_2"]


def test_an_idle_stream_sends_heartbeats(store: MapStore, make_client: ClientFactory, site: dict[str, int]) -> None:
    with make_client(store, **FAST).stream("GET", URL) as response:
        lines = response.iter_lines()
        seen = [next(lines) for _ in range(12)]

    assert ": heartbeat" in seen


def test_the_stream_ends_when_the_client_goes(store: MapStore, make_client: ClientFactory,
                                              site: dict[str, int]) -> None:
    client = make_client(store, **FAST)
    streams = _context(client).events

    with client.stream("GET", URL, params={"after": 0}) as response:
        lines = response.iter_lines()  # dropping the iterator would close the response
        _read(lines, 2)
        assert streams.open == 1

    wait_for(lambda: streams.open == 0, timeout_s=5.0, what="the event stream to close")


@pytest.mark.parametrize(("path", "params", "headers", "status", "message"), [
    (URL, {}, {"Last-Event-ID": "abc"}, 422, "Last-Event-ID must be a revision id"),
    (URL, {}, {"Last-Event-ID": "-3"}, 422, "Last-Event-ID must be a revision id"),
    (URL, {}, {"Last-Event-ID": "1" * 30}, 422, "at most 20 characters"),
    (URL, {"after": -1}, {}, 422, "greater than or equal to 0"),
    (URL, {"after": "x"}, {}, 422, "valid integer"),
    ("/v1/maps/nowhere/events", {}, {}, 404, "no map named 'nowhere'"),
    (URL, {}, {"Last-Event-ID": "999999"}, 409, "beyond the newest revision of map 'site'"),
    (URL, {"after": 999999}, {}, 409, "beyond the newest revision of map 'site'"),
])
def test_bad_cursors_are_a_clear_4xx(store: MapStore, make_client: ClientFactory, site: dict[str, int], path: str,
                                     params: dict[str, Any], headers: dict[str, str], status: int,
                                     message: str) -> None:
    client = make_client(store, **FAST)

    response = client.get(path, params=params, headers=headers)

    assert response.status_code == status
    assert message in str(response.json()["detail"])
    assert _context(client).events.open == 0


def test_events_need_a_key_when_reads_do(store: MapStore, make_client: ClientFactory, site: dict[str, int]) -> None:
    response = make_client(store, require_keys_for_reads=True, **FAST).get(URL)

    assert response.status_code == 401


def test_idle_streams_share_one_look_at_the_store_per_poll(store: MapStore, make_client: ClientFactory,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    poll_s = 0.05
    client = make_client(store, event_poll_s=poll_s, event_heartbeat_s=0.1)
    _write(store, "site", 2)
    calls: list[str] = []
    for name in ("latest_revision", "revisions"):
        monkeypatch.setattr(MapStore, name, _counted(getattr(MapStore, name), name, calls))
    with (client.stream("GET", URL) as first, client.stream("GET", URL) as second,
          client.stream("GET", URL) as third):
        streams = [response.iter_lines() for response in (first, second, third)]
        for lines in streams:
            next(lines)  # the opening comment: every stream is polling now
        calls.clear()
        start = time.monotonic()
        for lines in streams:
            _read_heartbeats(lines, 3)
        window_s = time.monotonic() - start
        looked = list(calls)

    assert "revisions" not in looked  # nothing new: no stream reads a page
    assert looked.count("latest_revision") <= window_s / poll_s + 2  # one look a poll, not one per stream


def _counted(method: Callable[..., Any], name: str, calls: list[str]) -> Callable[..., Any]:
    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(name)
        return method(*args, **kwargs)

    return counted


def _read_heartbeats(lines: Iterator[str], count: int) -> None:
    seen = 0
    while seen < count:
        seen += next(lines) == ": heartbeat"
