"""API keys of the REST API: created, listed, verified and revoked here; only salted hashes are stored.

A key's secret reads ``aisle_<key_id>_<token>``: ``key_id`` is a short public prefix (12 hex
characters) that names the key in lists and logs; the database holds only a random per-key
salt and the scrypt hash of the whole secret, so a leaked database gives no usable key.
"""

from __future__ import annotations

import datetime as dt
import enum
import hashlib
import hmac
import re
import secrets
from dataclasses import dataclass

import sqlalchemy as sa

from shared.store import schema
from shared.store.records import StoreError
from shared.store.store import MapStore

SECRET_PREFIX = "aisle"
KEY_ID_PATTERN = re.compile(r"[0-9a-f]{12}")
"""What a public key id looks like."""
_SECRET_PATTERN = re.compile(rf"{SECRET_PREFIX}_(?P<key_id>[0-9a-f]{{12}})_(?P<token>[A-Za-z0-9_-]{{43}})")
_SALT_BYTES = 16
_SCRYPT_N = 2**14
_SCRYPT_R = 8
_SCRYPT_P = 1
_HASH_BYTES = 32
MAX_NAME_LENGTH = 64
_FIRST_ADMIN_LOCK = 0x41_49_53_4C_45  # "AISLE": the advisory lock taken while making the first admin key


class Role(enum.StrEnum):
    """What a key may do: ``read`` < ``write`` (change the map) < ``admin`` (manage keys)."""

    READ = "read"
    WRITE = "write"
    ADMIN = "admin"

    def covers(self, required: Role) -> bool:
        """Whether a key of this role may do what needs ``required``."""
        return _RANK[self] >= _RANK[required]


_RANK = {Role.READ: 0, Role.WRITE: 1, Role.ADMIN: 2}


class ApiKeyError(StoreError, ValueError):
    """A key operation asked with bad input (unknown role, empty name, malformed key id)."""


@dataclass(frozen=True, slots=True)
class ApiKey:
    """A stored key as anyone may see it: never its secret or hash."""

    key_id: str
    name: str
    role: Role
    created_at: dt.datetime
    revoked_at: dt.datetime | None

    @property
    def active(self) -> bool:
        return self.revoked_at is None


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _aware(value: dt.datetime | None) -> dt.datetime | None:
    return value if value is None or value.tzinfo else value.replace(tzinfo=dt.UTC)


def _hash(secret: str, salt: bytes) -> bytes:
    return hashlib.scrypt(secret.encode(), salt=salt, n=_SCRYPT_N, r=_SCRYPT_R, p=_SCRYPT_P, dklen=_HASH_BYTES)


def _record(row: sa.Row[tuple[object, ...]]) -> ApiKey:
    mapping = row._mapping
    return ApiKey(str(mapping["key_id"]), str(mapping["name"]), Role(mapping["role"]),
                  _aware(mapping["created_at"]) or _now(), _aware(mapping["revoked_at"]))


def parse_key_id(secret: str) -> str | None:
    """The public key id of a well-formed secret, else None (no database access)."""
    match = _SECRET_PATTERN.fullmatch(secret)
    return None if match is None else match["key_id"]


def create_key(store: MapStore, *, role: Role | str, name: str) -> tuple[str, str]:
    """Create a key; returns ``(key_id, secret)``. The secret is shown only now and never stored.

    Parameters
    ----------
    store : MapStore
        A store upgraded to the current schema.
    role : Role or str
        ``read``, ``write`` or ``admin``.
    name : str
        Who the key is for, e.g. ``wms`` (1 to 64 characters).
    """
    try:
        checked_role = Role(role)
    except ValueError as err:
        raise ApiKeyError(f"unknown role {role!r}; roles: {[r.value for r in Role]}") from err
    name = name.strip()
    if not 0 < len(name) <= MAX_NAME_LENGTH:
        raise ApiKeyError(f"key name must be 1 to {MAX_NAME_LENGTH} characters, not {len(name)}")
    with store._begin() as connection:  # the store's own error translation
        return _insert_key(connection, role=checked_role, name=name)


def _insert_key(connection: sa.Connection, *, role: Role, name: str) -> tuple[str, str]:
    key_id = secrets.token_hex(6)
    secret = f"{SECRET_PREFIX}_{key_id}_{secrets.token_urlsafe(32)}"
    salt = secrets.token_bytes(_SALT_BYTES)
    connection.execute(schema.api_keys.insert().values(
        key_id=key_id, name=name, role=role.value, salt=salt, secret_hash=_hash(secret, salt),
        created_at=_now(), revoked_at=None,
    ))
    return key_id, secret


def list_keys(store: MapStore, *, include_revoked: bool = False) -> list[ApiKey]:
    """Every key, oldest first; revoked ones only if ``include_revoked``."""
    table = schema.api_keys
    query = sa.select(table).order_by(table.c.id)
    if not include_revoked:
        query = query.where(table.c.revoked_at.is_(None))
    with store._read() as connection:
        return [_record(row) for row in connection.execute(query)]


def get_key(store: MapStore, *, key_id: str) -> ApiKey | None:
    """The key with public id ``key_id`` (revoked or not), or None."""
    if KEY_ID_PATTERN.fullmatch(key_id) is None:
        return None
    table = schema.api_keys
    with store._read() as connection:
        row = connection.execute(sa.select(table).where(table.c.key_id == key_id)).first()
    return None if row is None else _record(row)


def verify_key(store: MapStore, *, secret: str) -> ApiKey | None:
    """The active key whose secret is ``secret``, or None (malformed, unknown, revoked or wrong)."""
    key_id = parse_key_id(secret)
    if key_id is None:
        return None
    table = schema.api_keys
    with store._read() as connection:
        row = connection.execute(sa.select(table).where(table.c.key_id == key_id)).first()
    if row is None or row.revoked_at is not None:
        return None
    if not hmac.compare_digest(_hash(secret, bytes(row.salt)), bytes(row.secret_hash)):
        return None
    return _record(row)


def revoke_key(store: MapStore, *, key_id: str) -> ApiKey | None:
    """Revoke key ``key_id`` from now on; returns it, or None if there is no such key.

    Revoking a revoked key keeps its first revocation time.
    """
    if KEY_ID_PATTERN.fullmatch(key_id) is None:
        raise ApiKeyError(f"key id {key_id!r} is not 12 lowercase hex characters")
    table = schema.api_keys
    with store._begin() as connection:
        connection.execute(table.update().where(table.c.key_id == key_id, table.c.revoked_at.is_(None))
                           .values(revoked_at=_now()))
        row = connection.execute(sa.select(table).where(table.c.key_id == key_id)).first()
    return None if row is None else _record(row)


def ensure_admin_key(store: MapStore, *, name: str = "first-admin") -> str | None:
    """Create and return the secret of a first admin key when no active admin key exists, else None.

    The embedded stack calls this at start and prints the secret once; a later start prints nothing. API
    processes starting together on one PostgreSQL database (a deployment) make one key between them: the check
    and the insert run in one transaction under an advisory lock.
    """
    table = schema.api_keys
    with store._begin() as connection:
        if connection.dialect.name == "postgresql":
            connection.execute(sa.text("SELECT pg_advisory_xact_lock(:key)"), {"key": _FIRST_ADMIN_LOCK})
        found = connection.execute(sa.select(table.c.id).where(
            table.c.role == Role.ADMIN.value, table.c.revoked_at.is_(None)).limit(1)).first()
        if found is not None:
            return None
        return _insert_key(connection, role=Role.ADMIN, name=name)[1]
