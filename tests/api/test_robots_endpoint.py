"""GET /v1/maps/{map}/robots: each robot's latest pose and track, as the occupancy stage stored them."""

from __future__ import annotations

import datetime as dt

from fastapi.testclient import TestClient

from shared.robots import Robot, TrackPoint
from shared.store import MapStore, RevisionWrite
from shared.vocabulary import REVISION_HEADER

URL = "/v1/maps/site/robots"
S = 1_000_000_000


def _write(store: MapStore, *robots: Robot) -> int:
    site = store.ensure_map("site").id
    features = {"robot": [robot.feature() for robot in robots]}
    return store.write_revision(site, RevisionWrite("occupancy_mapping", features=features)).id


def _robot(name: str, x: float, stamp_s: int) -> Robot:
    track = tuple(TrackPoint(x - i, 2.0, 0.0, (stamp_s - i) * S) for i in reversed(range(3)))
    return Robot(name, track[-1], track)


def test_robots_come_with_their_pose_track_and_time(client: TestClient, store: MapStore) -> None:
    revision = _write(store, _robot("robot2", 5.0, 1_767_225_600), _robot("robot1", 9.0, 1_767_225_600))

    response = client.get(URL)

    assert response.status_code == 200 and response.headers[REVISION_HEADER] == str(revision)
    robots = response.json()["robots"]
    assert [r["robot"] for r in robots] == ["robot1", "robot2"]
    first = robots[0]
    assert first["pose"] == {"x_m": 9.0, "y_m": 2.0, "yaw_rad": 0.0, "stamp_ns": 1_767_225_600 * S}
    assert dt.datetime.fromisoformat(first["seen_at"]) == dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    assert [p["x_m"] for p in first["track"]] == [7.0, 8.0, 9.0]
    assert first["revision_id"] == revision


def test_robots_as_at_an_earlier_revision_are_where_they_were_then(client: TestClient, store: MapStore) -> None:
    earlier = _write(store, _robot("robot1", 1.0, 100))
    _write(store, _robot("robot1", 4.0, 103))

    assert client.get(URL).json()["robots"][0]["pose"]["x_m"] == 4.0
    assert client.get(URL, params={"revision": earlier}).json()["robots"][0]["pose"]["x_m"] == 1.0


def test_a_map_without_robots_answers_an_empty_list(client: TestClient, store: MapStore) -> None:
    store.ensure_map("site")

    assert client.get(URL).json() == {"robots": []}
    assert client.get("/v1/maps/nowhere/robots").status_code == 404
