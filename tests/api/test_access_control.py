"""API keys on the wire: 401 without a key, 403 below the needed role, 429 over the rate limit; nothing changes."""

from __future__ import annotations

from typing import NamedTuple

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from api.access import required_role
from api.errors import ApiConfigError
from shared.store import MapStore
from shared.store.keys import Role, create_key, ensure_admin_key, list_keys, revoke_key
from tests.api.conftest import ClientFactory

WRITE_PROBE = "/v1/test/write-probe"


class Keys(NamedTuple):
    read: str
    write: str
    admin: str


@pytest.fixture
def keys(store: MapStore) -> Keys:
    return Keys(*(create_key(store, role=role, name=f"{role.value}-client")[1] for role in Role))


def _with_write_probe(client: TestClient) -> TestClient:
    """Add a POST route after create_app, as a future write endpoint would be: the app-wide rules cover it."""
    app = client.app
    assert isinstance(app, FastAPI)

    @app.post(WRITE_PROBE)
    def probe() -> dict[str, bool]:
        return {"written": True}

    return client


def _auth(secret: str) -> dict[str, str]:
    return {"X-API-Key": secret}


def test_a_write_needs_a_write_key(store: MapStore, make_client: ClientFactory, keys: Keys) -> None:
    client = _with_write_probe(make_client(store))

    anonymous = client.post(WRITE_PROBE)
    reader = client.post(WRITE_PROBE, headers=_auth(keys.read))

    assert anonymous.status_code == 401
    assert "X-API-Key" in anonymous.json()["detail"]
    assert "Bearer" in anonymous.headers["WWW-Authenticate"]
    assert reader.status_code == 403
    assert "role 'read'" in reader.json()["detail"] and "'write'" in reader.json()["detail"]
    assert client.post(WRITE_PROBE, headers=_auth(keys.write)).json() == {"written": True}
    assert client.post(WRITE_PROBE, headers=_auth(keys.admin)).status_code == 200
    assert client.post(WRITE_PROBE, headers={"Authorization": f"Bearer {keys.write}"}).status_code == 200


def test_reads_are_open_by_default_and_need_a_read_key_when_required(
    store: MapStore, make_client: ClientFactory, keys: Keys, site: dict[str, int]
) -> None:
    open_reads = make_client(store)
    closed_reads = make_client(store, require_keys_for_reads=True)

    assert open_reads.get("/v1/maps").status_code == 200
    assert closed_reads.get("/v1/maps").status_code == 401
    assert closed_reads.get("/v1/maps", headers=_auth(keys.read)).status_code == 200
    assert closed_reads.get("/v1/maps/site/bins", headers={"Authorization": f"Bearer {keys.read}"}).status_code == 200
    assert closed_reads.get("/v1/health").status_code in {200, 503}  # probes need no key


@pytest.mark.parametrize(("secret", "message"), [
    ("not-a-key", "malformed API key"),
    ("aisle_0123456789ab_" + "A" * 43, "API key 0123456789ab is unknown"),
    ("' OR 1=1 --", "malformed API key"),
])
def test_bad_keys_are_401_without_echoing_the_secret(
    store: MapStore, make_client: ClientFactory, secret: str, message: str
) -> None:
    response = make_client(store).get("/v1/maps", headers=_auth(secret))

    assert response.status_code == 401
    assert message in response.json()["detail"]
    assert secret not in response.json()["detail"]


def test_a_wrong_secret_for_a_real_key_id_is_401(store: MapStore, make_client: ClientFactory, keys: Keys) -> None:
    wrong = keys.write[:-1] + ("A" if keys.write[-1] != "A" else "B")

    response = make_client(store).get("/v1/maps", headers=_auth(wrong))

    assert response.status_code == 401
    assert "wrong secret" in response.json()["detail"]


def test_a_revoked_key_stops_working_at_once(store: MapStore, make_client: ClientFactory, keys: Keys) -> None:
    client = _with_write_probe(make_client(store))
    assert client.post(WRITE_PROBE, headers=_auth(keys.write)).status_code == 200  # now verified and remembered

    key_id = keys.write.split("_")[1]
    revoke_key(store, key_id=key_id)
    response = client.post(WRITE_PROBE, headers=_auth(keys.write))

    assert response.status_code == 401
    assert response.json()["detail"] == f"API key {key_id} is revoked"


def test_key_management_needs_an_admin_key_and_refusals_change_nothing(
    store: MapStore, make_client: ClientFactory, keys: Keys
) -> None:
    client = make_client(store)
    before = list_keys(store, include_revoked=True)
    victim = before[0].key_id

    for secret in (None, keys.read, keys.write):
        headers = {} if secret is None else _auth(secret)
        expected = 401 if secret is None else 403
        assert client.get("/v1/keys", headers=headers).status_code == expected
        assert client.post("/v1/keys", json={"name": "x", "role": "admin"}, headers=headers).status_code == expected
        assert client.delete(f"/v1/keys/{victim}", headers=headers).status_code == expected

    assert list_keys(store, include_revoked=True) == before


def test_admin_creates_lists_and_revokes_keys(store: MapStore, make_client: ClientFactory, keys: Keys) -> None:
    client = _with_write_probe(make_client(store))
    admin = _auth(keys.admin)

    created = client.post("/v1/keys", json={"name": "wms", "role": "write"}, headers=admin)
    assert created.status_code == 201
    body = created.json()
    assert body["role"] == "write" and body["name"] == "wms" and body["revoked_at"] is None
    assert client.post(WRITE_PROBE, headers=_auth(body["secret"])).status_code == 200

    listed = client.get("/v1/keys", headers=admin).json()
    assert body["key_id"] in [key["key_id"] for key in listed]
    assert all("secret" not in key for key in listed)

    revoked = client.delete(f"/v1/keys/{body['key_id']}", headers=admin)
    assert revoked.status_code == 200 and revoked.json()["revoked_at"] is not None
    assert client.post(WRITE_PROBE, headers=_auth(body["secret"])).status_code == 401
    assert body["key_id"] not in [key["key_id"] for key in client.get("/v1/keys", headers=admin).json()]
    everything = client.get("/v1/keys", params={"include_revoked": "true"}, headers=admin).json()
    assert body["key_id"] in [key["key_id"] for key in everything]


@pytest.mark.parametrize(("body", "field"), [
    ({"name": "wms", "role": "owner"}, "role"),
    ({"name": "", "role": "read"}, "name"),
    ({"name": "a" * 65, "role": "read"}, "name"),
    ({"name": "wms'; DROP TABLE api_keys; --", "role": "read"}, "name"),
    ({"role": "read"}, "name"),
])
def test_bad_key_requests_are_422_and_create_nothing(
    store: MapStore, make_client: ClientFactory, keys: Keys, body: dict[str, str], field: str
) -> None:
    before = list_keys(store, include_revoked=True)

    response = make_client(store).post("/v1/keys", json=body, headers=_auth(keys.admin))

    assert response.status_code == 422
    assert field in str(response.json()["detail"])
    assert list_keys(store, include_revoked=True) == before


def test_revoking_unknown_malformed_or_last_admin_keys_is_refused(
    store: MapStore, make_client: ClientFactory, keys: Keys
) -> None:
    client = make_client(store)
    admin = _auth(keys.admin)
    admin_id = keys.admin.split("_")[1]

    unknown = client.delete("/v1/keys/0123456789ab", headers=admin)
    malformed = client.delete("/v1/keys/..%2F..%2Fetc", headers=admin)
    last_admin = client.delete(f"/v1/keys/{admin_id}", headers=admin)

    assert unknown.status_code == 404 and "no API key 0123456789ab" in unknown.json()["detail"]
    assert malformed.status_code in {404, 422}
    assert last_admin.status_code == 409 and "last active admin key" in last_admin.json()["detail"]
    assert all(key.active for key in list_keys(store, include_revoked=True))


def test_the_first_admin_key_manages_keys(store: MapStore, make_client: ClientFactory) -> None:
    secret = ensure_admin_key(store)
    assert secret is not None

    response = make_client(store).post("/v1/keys", json={"name": "wms", "role": "read"}, headers=_auth(secret))

    assert response.status_code == 201


def test_over_the_rate_limit_is_429_with_retry_after_per_key(
    store: MapStore, make_client: ClientFactory, keys: Keys
) -> None:
    client = make_client(store, rate_limit_per_s=0.01, rate_limit_burst=2)

    statuses = [client.get("/v1/maps", headers=_auth(keys.read)).status_code for _ in range(3)]
    limited = client.get("/v1/maps", headers=_auth(keys.read))

    assert statuses == [200, 200, 429]
    assert limited.status_code == 429
    assert int(limited.headers["Retry-After"]) >= 1
    assert "rate limit" in limited.json()["detail"]
    assert client.get("/v1/maps", headers=_auth(keys.write)).status_code == 200  # its own bucket


def test_no_rate_limit_when_disabled(store: MapStore, make_client: ClientFactory) -> None:
    client = make_client(store, rate_limit_per_s=None)

    assert {client.get("/v1/maps").status_code for _ in range(50)} == {200}


def test_cors_allows_configured_origins_only(store: MapStore, make_client: ClientFactory) -> None:
    client = make_client(store, cors_origins=["https://wms.example.com"])
    preflight = {"Access-Control-Request-Method": "GET", "Access-Control-Request-Headers": "X-API-Key"}

    allowed = client.options("/v1/maps", headers={"Origin": "https://wms.example.com", **preflight})
    refused = client.options("/v1/maps", headers={"Origin": "https://evil.example.com", **preflight})
    plain = client.get("/v1/maps", headers={"Origin": "https://wms.example.com"})

    assert allowed.status_code == 200
    assert allowed.headers["access-control-allow-origin"] == "https://wms.example.com"
    assert "x-api-key" in allowed.headers["access-control-allow-headers"].lower()
    assert "access-control-allow-origin" not in refused.headers
    assert plain.headers["access-control-allow-origin"] == "https://wms.example.com"
    assert "access-control-allow-origin" not in make_client(store).get(
        "/v1/maps", headers={"Origin": "https://wms.example.com"}).headers


@pytest.mark.parametrize(("options", "message"), [
    ({"cors_origins": ["wms.example.com"]}, "CORS origin 'wms.example.com'"),
    ({"cors_origins": ["https://wms.example.com/"]}, "without a trailing slash"),
    ({"rate_limit_per_s": 0.0}, "positive number of requests per second"),
    ({"rate_limit_burst": 0}, "at least 1 request"),
    ({"event_poll_s": -1.0}, "event poll interval"),
])
def test_nonsense_options_fail_at_create_app(
    store: MapStore, make_client: ClientFactory, options: dict[str, object], message: str
) -> None:
    with pytest.raises(ApiConfigError, match=message):
        make_client(store, **options)


@pytest.mark.parametrize(("method", "path", "reads_need_keys", "expected"), [
    ("GET", "/v1/maps", False, None),
    ("GET", "/v1/maps", True, Role.READ),
    ("HEAD", "/v1/maps", True, Role.READ),
    ("GET", "/v1/health", True, None),
    ("POST", "/v1/maps", False, Role.WRITE),
    ("delete", "/v1/anything", False, Role.WRITE),
    ("PATCH", "/v1/health", True, Role.WRITE),
])
def test_required_role_by_method_and_path(method: str, path: str, reads_need_keys: bool,
                                          expected: Role | None) -> None:
    assert required_role(method, path, require_keys_for_reads=reads_need_keys) is expected


def test_openapi_documents_both_ways_to_send_a_key(store: MapStore, make_client: ClientFactory) -> None:
    schema = make_client(store).get("/openapi.json").json()

    schemes = schema["components"]["securitySchemes"]
    assert schemes["ApiKey"] == {"type": "apiKey", "in": "header", "name": "X-API-Key",
                                 "description": schemes["ApiKey"]["description"]}
    assert schemes["Bearer"]["scheme"] == "bearer"
    assert {"/v1/keys", "/v1/maps/{map_name}/bins", "/v1/maps/{map_name}/events"} <= schema["paths"].keys()
