"""Verified API keys are remembered: a revoked key stops reading within ``recheck_s`` (and changing anything at
once), and concurrent first requests with one key verify it once; cached builds are made once too."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import pytest
from fastapi import HTTPException

from api.access import AccessPolicy, Caller, Credentials
from atlas.cache import RevisionCache
from shared.store import MapStore
from shared.store.keys import Role, create_key, revoke_key


class FakeClock:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


def _policy(clock: FakeClock) -> AccessPolicy:
    return AccessPolicy(require_keys_for_reads=True, rate_limit_per_s=None, rate_limit_burst=1, recheck_s=1.0,
                        clock=clock)


def test_a_revoked_key_stops_reading_within_the_recheck_interval(store: MapStore) -> None:
    clock = FakeClock()
    policy = _policy(clock)
    key_id, secret = create_key(store, role=Role.READ, name="wms")
    policy.authenticate(store, secret, address="10.0.0.1")

    revoke_key(store, key_id=key_id)
    clock.now += 0.5
    still_trusted = policy.remembered(secret)
    clock.now += 0.6
    rechecked = policy.remembered(secret)
    with pytest.raises(HTTPException) as refused:
        policy.authenticate(store, secret, address="10.0.0.1")

    assert still_trusted is not None and still_trusted.key_id == key_id
    assert rechecked is None
    assert refused.value.status_code == 401 and refused.value.detail == f"API key {key_id} is revoked"


def test_a_revoked_key_changes_nothing_from_that_moment(store: MapStore) -> None:
    policy = _policy(FakeClock())
    key_id, secret = create_key(store, role=Role.WRITE, name="operator")
    policy.authenticate(store, secret, address="10.0.0.1")

    revoke_key(store, key_id=key_id)

    with pytest.raises(HTTPException) as refused:
        policy.authenticate(store, secret, address="10.0.0.1", fresh=True)  # what a write does
    assert refused.value.status_code == 401


def test_a_remembered_key_needs_its_own_secret(store: MapStore) -> None:
    policy = _policy(FakeClock())
    key_id, secret = create_key(store, role=Role.READ, name="wms")
    policy.authenticate(store, secret, address="10.0.0.1")
    forged = secret[:-1] + ("A" if secret[-1] != "A" else "B")

    assert policy.remembered(forged) is None
    with pytest.raises(HTTPException) as refused:
        policy.authenticate(store, forged, address="10.0.0.1")
    assert refused.value.detail == f"wrong secret for API key {key_id}"


def test_concurrent_first_requests_with_one_key_verify_it_once(store: MapStore) -> None:
    policy = _policy(FakeClock())
    key_id, secret = create_key(store, role=Role.READ, name="wms")

    with ThreadPoolExecutor(8) as pool:
        callers = list(pool.map(lambda _: policy.authenticate(store, secret, address="10.0.0.1"), range(8)))

    assert {caller.key.key_id for caller in callers if caller.key is not None} == {key_id}
    assert len(callers) == 8
    assert policy.secrets_hashed == 1


def test_concurrent_gets_of_one_missing_entry_build_it_once() -> None:
    cache = RevisionCache(size=4)
    builds = []

    def build() -> str:
        builds.append(1)
        threading.Event().wait(0.2)  # long enough for the other callers to ask meanwhile
        return "index"

    with ThreadPoolExecutor(8) as pool:
        values = list(pool.map(lambda _: cache.get(("bins", 1), build), range(8)))

    assert values == ["index"] * 8
    assert len(builds) == 1


def test_a_failed_build_is_not_cached_and_the_next_get_builds_again() -> None:
    cache = RevisionCache(size=4)

    def fail() -> str:
        raise RuntimeError("database went away")

    with pytest.raises(RuntimeError):
        cache.get("key", fail)

    assert cache.get("key", lambda: "built") == "built"


def test_memory_decides_reads_with_a_remembered_key_and_requests_without_a_key(store: MapStore) -> None:
    policy = _policy(FakeClock())
    key_id, secret = create_key(store, role=Role.READ, name="wms")
    bins = "/v1/maps/{map_name}/bins/{bin_id}"
    before = policy.judge(Credentials(secret, "10.0.0.1"), method="GET", route=bins)
    policy.authenticate(store, secret, address="10.0.0.1")

    read = policy.judge(Credentials(secret, "10.0.0.1"), method="GET", route=bins)
    write = policy.judge(Credentials(secret, "10.0.0.1"), method="POST", route=bins)
    anonymous = policy.judge(Credentials(None, "10.0.0.1"), method="GET", route=bins)
    malformed = policy.judge(Credentials("not-a-key", "10.0.0.1"), method="POST", route=bins)

    assert before is None and write is None  # the key's row must be read
    assert read is not None and read.refusal is None and read.bucket == f"key:{key_id}"
    assert anonymous is not None and anonymous.bucket == "address:10.0.0.1"
    assert anonymous.refusal is not None and anonymous.refusal.status_code == 401
    assert malformed is not None and malformed.refusal is not None
    assert malformed.refusal.detail.startswith("malformed API key")


def test_a_verdict_is_charged_once_when_settled_and_never_when_judged(store: MapStore) -> None:
    policy = AccessPolicy(require_keys_for_reads=False, rate_limit_per_s=0.001, rate_limit_burst=2,
                          clock=FakeClock())
    anonymous = Credentials(None, "10.0.0.1")
    verdicts = [policy.judge(anonymous, method="GET", route="/v1/maps") for _ in range(5)]

    settled = [policy.settle(verdict) for verdict in verdicts[:2] if verdict is not None]
    with pytest.raises(HTTPException) as limited:
        policy.admit(store, anonymous, method="GET", route="/v1/maps")

    assert settled == [Caller(None, "10.0.0.1")] * 2
    assert limited.value.status_code == 429 and limited.value.headers is not None
    assert int(limited.value.headers["Retry-After"]) >= 1
