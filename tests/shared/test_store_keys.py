"""shared.store.keys: API keys stored as salted hashes, verified, listed and revoked; on both backends."""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext

from shared.store import MapStore, schema
from shared.store.keys import (
    ApiKeyError,
    Role,
    create_key,
    ensure_admin_key,
    get_key,
    list_keys,
    parse_key_id,
    revoke_key,
    verify_key,
)


def test_migrations_build_exactly_the_schema_in_schema_py(store: MapStore) -> None:
    with store.engine.connect() as connection:
        differences = compare_metadata(MigrationContext.configure(connection), schema.metadata)

    assert differences == []


def test_created_key_verifies_and_its_secret_is_not_stored(store: MapStore) -> None:
    key_id, secret = create_key(store, role=Role.WRITE, name="wms")

    key = verify_key(store, secret=secret)
    assert key is not None
    assert (key.key_id, key.name, key.role, key.active) == (key_id, "wms", Role.WRITE, True)
    assert parse_key_id(secret) == key_id
    with store.engine.connect() as connection:
        row = connection.execute(sa.select(schema.api_keys)).one()
    stored = b"".join(bytes(v) if isinstance(v, bytes | memoryview) else str(v).encode() for v in row)
    assert secret.encode() not in stored
    assert secret.rsplit("_", 1)[-1].encode() not in stored


def test_each_key_gets_its_own_salt(store: MapStore) -> None:
    create_key(store, role="read", name="a")
    create_key(store, role="read", name="b")

    with store.engine.connect() as connection:
        salts = connection.execute(sa.select(schema.api_keys.c.salt)).scalars().all()
    assert len(set(salts)) == 2


@pytest.mark.parametrize("mangle", [
    lambda s: s[:-1] + ("A" if s[-1] != "A" else "B"),  # wrong token
    lambda s: s.replace("aisle_", "aisel_"),  # malformed
    lambda s: s + "x",  # too long
    lambda s: "",
    lambda s: "aisle_000000000000_" + s.rsplit("_", 1)[-1],  # unknown id
    lambda s: "x' OR '1'='1",
])
def test_wrong_or_malformed_secrets_do_not_verify(store: MapStore, mangle: Callable[[str], str]) -> None:
    _, secret = create_key(store, role=Role.ADMIN, name="ops")

    assert verify_key(store, secret=mangle(secret)) is None


def test_revoked_key_no_longer_verifies_and_is_listed_only_on_request(store: MapStore) -> None:
    kept_id, _ = create_key(store, role=Role.READ, name="dashboard")
    gone_id, secret = create_key(store, role=Role.WRITE, name="old wms")

    revoked = revoke_key(store, key_id=gone_id)
    again = revoke_key(store, key_id=gone_id)

    assert revoked is not None and revoked.revoked_at is not None
    assert again is not None and again.revoked_at == revoked.revoked_at
    assert verify_key(store, secret=secret) is None
    assert [k.key_id for k in list_keys(store)] == [kept_id]
    assert [k.key_id for k in list_keys(store, include_revoked=True)] == [kept_id, gone_id]
    found = get_key(store, key_id=gone_id)
    assert found is not None and not found.active


def test_revoking_an_unknown_key_gives_none_and_a_malformed_id_is_refused(store: MapStore) -> None:
    assert revoke_key(store, key_id="0123456789ab") is None
    with pytest.raises(ApiKeyError, match="12 lowercase hex"):
        revoke_key(store, key_id="1; DROP TABLE api_keys")
    assert get_key(store, key_id="1; DROP TABLE api_keys") is None


@pytest.mark.parametrize(("role", "name", "message"), [
    ("owner", "wms", "unknown role 'owner'"),
    ("read", "", "1 to 64 characters"),
    ("read", "   ", "1 to 64 characters"),
    ("read", "n" * 65, "1 to 64 characters"),
])
def test_create_key_refuses_bad_role_or_name(store: MapStore, role: str, name: str, message: str) -> None:
    with pytest.raises(ApiKeyError, match=message):
        create_key(store, role=role, name=name)
    assert list_keys(store, include_revoked=True) == []


def test_ensure_admin_key_creates_one_only_while_there_is_no_active_admin(store: MapStore) -> None:
    first = ensure_admin_key(store)

    assert first is not None
    key = verify_key(store, secret=first)
    assert key is not None and key.role is Role.ADMIN
    assert ensure_admin_key(store) is None
    revoke_key(store, key_id=key.key_id)
    assert ensure_admin_key(store) is not None


@pytest.mark.postgres
def test_api_processes_starting_together_make_one_first_admin_key(postgres_url: str) -> None:
    stores = [MapStore(postgres_url) for _ in range(4)]  # one per `aisle serve` of a deployment
    stores[0].upgrade()
    start = threading.Barrier(len(stores))

    def first_key(store: MapStore) -> str | None:
        start.wait()
        return ensure_admin_key(store)

    with ThreadPoolExecutor(len(stores)) as pool:
        printed = [secret for secret in pool.map(first_key, stores) if secret is not None]
    assert len(printed) == 1
    assert [key.role for key in list_keys(stores[0])] == [Role.ADMIN]
    for store in stores:
        store.close()


def test_roles_are_ordered_read_write_admin() -> None:
    assert Role.ADMIN.covers(Role.WRITE) and Role.WRITE.covers(Role.READ) and Role.READ.covers(Role.READ)
    assert not Role.READ.covers(Role.WRITE) and not Role.WRITE.covers(Role.ADMIN)
