"""Live reads come from memory: at most ``staleness_s`` behind the store, never behind what the API itself wrote,
and answered the same whether FastAPI's route or the in-memory fast path serves them."""

from __future__ import annotations

import asyncio
import threading
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from atlas.cache import RevisionCache
from atlas.live import LiveMaps
from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus
from shared.store import Feature, GridLayer, MapStore, RevisionWrite
from shared.store.keys import Role, create_key
from shared.worker import MAP_EVENTS_TOPIC, map_event
from tests.api.conftest import ClientFactory
from tests.helpers import wait_for

FEATURES = "/v1/maps/site/features"


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def _bin(key: str, x: float) -> Feature:
    return Feature("bin", key, {"type": "Point", "coordinates": [x, 1.0]}, {"level": 0}, 0.9)


def test_a_live_answer_is_at_most_the_staleness_bound_behind_the_store(store: MapStore, site: dict[str, int]) -> None:
    clock = FakeClock()
    live = LiveMaps(store, RevisionCache(), staleness_s=0.2, clock=clock)
    site_map = store.ensure_map("site")
    first = asyncio.run(live.get(site_map))
    assert first is not None and first.revision_id == site["semantics_2"]

    written = store.write_revision(site_map.id, RevisionWrite("semantics", features={"bin": [_bin("B9", 9.0)]})).id
    clock.now += 0.05  # within the bound, and not yet time to look: the answer may be behind
    within = asyncio.run(live.get(site_map))
    clock.now += 0.2  # past the bound: the answer must cover the new revision
    past = asyncio.run(live.get(site_map))

    assert within is first
    assert past is not None and past.revision_id == written
    assert past.features.feature("bin", "B9") is not None and past.features.feature("bin", "B1") is None


def test_a_client_reads_the_revisions_it_wrote_through_the_api(store: MapStore, make_client: ClientFactory,
                                                               site: dict[str, int]) -> None:
    admin = {"X-API-Key": create_key(store, role=Role.ADMIN, name="operator")[1]}
    client = make_client(store, live_staleness_s=60.0)  # nothing written beside the API would show for a minute
    before = client.get(FEATURES, params={"kind": "dock"})
    written = client.put("/v1/maps/site/places/dock/D7", headers=admin,
                         json={"geometry": {"type": "Point", "coordinates": [3.0, 4.0]}})
    after = client.get(FEATURES, params={"kind": "dock"})

    assert written.status_code in (200, 201), written.text
    assert "dock/D7" not in [f["id"] for f in before.json()["features"]]
    assert "dock/D7" in [f["id"] for f in after.json()["features"]]
    assert int(after.headers["X-Aisle-Revision-Id"]) > int(before.headers["X-Aisle-Revision-Id"])


def test_live_state_moves_on_without_rereading_features_for_layer_revisions(store: MapStore,
                                                                            site: dict[str, int]) -> None:
    clock = FakeClock()
    live = LiveMaps(store, RevisionCache(), staleness_s=0.0, clock=clock)
    site_map = store.ensure_map("site")
    first = asyncio.run(live.get(site_map))
    layer_only = store.write_revision(site_map.id, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", np.zeros((2, 2), dtype=np.int8), 0.5, 0.0, 0.0)])).id
    clock.now += 1.0
    second = asyncio.run(live.get(site_map))

    assert first is not None and second is not None
    assert second.revision_id == layer_only
    assert second.features.rows is first.features.rows and second.bins is first.bins


def test_concurrent_reads_of_a_stale_map_share_one_refresh(store: MapStore, site: dict[str, int]) -> None:
    live = LiveMaps(store, RevisionCache(), staleness_s=0.0)
    site_map = store.ensure_map("site")

    async def many() -> list[Any]:
        return await asyncio.gather(*(live.get(site_map) for _ in range(20)))

    answers = asyncio.run(many())

    assert len({id(answer) for answer in answers}) == 1  # one build, shared by all
    assert answers[0].revision_id == site["semantics_2"]


@pytest.mark.parametrize("require_keys", [False, True])
def test_bins_from_memory_are_the_bins_the_store_gives(store: MapStore, make_client: ClientFactory,
                                                       site: dict[str, int], require_keys: bool) -> None:
    headers = {"X-API-Key": create_key(store, role=Role.READ, name="wms")[1]} if require_keys else {}
    client = make_client(store, require_keys_for_reads=require_keys)
    answers = [client.get("/v1/maps/site/bins/B1", headers=headers) for _ in range(3)]  # route, then memory
    at_newest = client.get("/v1/maps/site/bins/B1", params={"revision": site["semantics_2"]}, headers=headers)

    assert [answer.status_code for answer in answers] == [200, 200, 200]
    assert answers[0].content == answers[1].content == answers[2].content
    assert answers[2].json() == at_newest.json()
    assert answers[2].headers["X-Aisle-Revision-Id"] == str(site["semantics_2"])


def test_reads_from_memory_keep_the_access_rules(store: MapStore, make_client: ClientFactory,
                                                site: dict[str, int]) -> None:
    secret = create_key(store, role=Role.READ, name="wms")[1]
    client = make_client(store, require_keys_for_reads=True, rate_limit_per_s=0.001, rate_limit_burst=3)
    with_key = [client.get(FEATURES, params={"bbox": "0,0,3,3"}, headers={"X-API-Key": secret}).status_code
                for _ in range(4)]
    without_key = client.get(FEATURES, params={"bbox": "0,0,3,3"})
    bad_bbox = client.get("/v1/maps/site/features", params={"bbox": "3,3,0,0"})

    assert with_key == [200, 200, 200, 429]
    assert without_key.status_code == 401
    assert bad_bbox.status_code == 401  # the key comes first, as on every route


def test_refused_and_unusual_live_reads_get_the_routes_answers(client: TestClient, site: dict[str, int]) -> None:
    client.get(FEATURES)  # the live state now answers from memory
    bad_bbox = client.get(FEATURES, params={"bbox": "3,3,0,0"})
    bad_kind = client.get(FEATURES, params={"kind": "unicorn"})
    bad_limit = client.get(FEATURES, params={"limit": "-1"})
    missing_bin = client.get("/v1/maps/site/bins/NOPE")
    bad_bin_id = client.get("/v1/maps/site/bins/%2Fetc")
    unknown_map = client.get("/v1/maps/nowhere/features")

    assert bad_bbox.status_code == bad_kind.status_code == bad_limit.status_code == 422
    assert "min greater than max" in bad_bbox.json()["detail"]
    assert "unicorn" in bad_kind.json()["detail"]
    assert missing_bin.status_code == 404 and "NOPE" in missing_bin.json()["detail"]
    assert bad_bin_id.status_code in (404, 422)
    assert unknown_map.status_code == 404


def test_a_revision_announced_on_the_bus_is_read_at_once(store: MapStore, site: dict[str, int],
                                                         bus_pair: tuple[Bus, Bus]) -> None:
    api_bus, stage_bus = bus_pair
    live = LiveMaps(store, RevisionCache(), staleness_s=3600.0)
    site_map = store.ensure_map("site")
    asyncio.run(live.get(site_map))
    refreshed = threading.Event()
    live.follow(api_bus)
    try:
        written = store.write_revision(site_map.id, RevisionWrite("semantics", features={"bin": [_bin("B8", 8.0)]}))
        publisher = stage_bus.publisher(MAP_EVENTS_TOPIC, messages.MAP_EVENT, namespace=WORKER_NAMESPACE)
        for _ in range(100):  # until the subscription is matched and the refresh done
            publisher.publish(map_event("site", written))
            now = live.peek(site_map)
            if now is not None and now.revision_id == written.id:
                refreshed.set()
                break
            threading.Event().wait(0.05)
    finally:
        live.close()

    assert refreshed.is_set()


def test_a_served_map_is_in_memory_before_its_first_read(store: MapStore, make_client: ClientFactory,
                                                         site: dict[str, int]) -> None:
    client = make_client(store, live_staleness_s=60.0)
    info = store.get_map("site")
    assert info is not None
    with client:  # the app starts (its lifespan runs) and nobody reads the map
        live = client.app.state.context.live  # type: ignore[attr-defined]
        wait_for(lambda: live.peek(info) is not None, what="the live state built ahead of any read")
        assert live.peek(info).revision_id == site["semantics_2"]
