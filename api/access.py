"""Who may call the API: API keys with roles, per-caller rate limits and which requests need which role.

Reads (GET, HEAD, OPTIONS) need a ``read`` key only when the app requires keys for reads;
everything that changes anything needs ``write`` (or ``admin``); key management needs ``admin``.
A key comes in ``X-API-Key: <secret>`` or ``Authorization: Bearer <secret>``.

One function decides every request, whichever path answers it: :meth:`AccessPolicy.admit` (its in-memory part,
:meth:`AccessPolicy.judge`, for what needs no store), from the :class:`Credentials` that
:func:`credentials_of` reads off the request.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from fastapi import HTTPException, status

from api.errors import ApiConfigError
from api.ratelimit import TokenBucketLimiter
from shared.store import MapStore
from shared.store.keys import ApiKey, Role, get_key, parse_key_id, verify_key

READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
OPEN_READ_PATHS = frozenset({"/v1/health", "/", "/viewer", "/viewer/{asset:path}"})
"""Route paths read without a key even when keys are required for reads: load balancer probes, and the map viewer's
page and files (they hold no map data; the page asks for a key when the map's reads need one)."""
API_KEY_HEADER = "X-API-Key"
_LOCK_STRIPES = 64
"""Locks that make one request per key verify it (keys share them by hash), bounded whatever ids callers send."""
CHALLENGE = {"WWW-Authenticate": f'Bearer, ApiKey header="{API_KEY_HEADER}"'}
_KEY_HEADER = API_KEY_HEADER.lower().encode("latin-1")


class Credentials(NamedTuple):
    """What a request presents: the API key it carries (None: none) and the client's address."""

    secret: str | None
    address: str


def credentials_of(scope: Mapping[str, Any]) -> Credentials:
    """The key and client address of an ASGI HTTP request, read as FastAPI reads them.

    The key is the first ``X-API-Key`` header if it is not empty (as ``APIKeyHeader``), else the credentials of
    the first ``Authorization`` header if its scheme is ``Bearer`` in any case and they are not empty (as
    ``HTTPBearer``); header values are Latin-1, as Starlette decodes them. The address is the client's host, or
    ``unknown`` when the server does not say.
    """
    api_key = authorization = None
    for name, value in scope["headers"]:
        if name == _KEY_HEADER and api_key is None:
            api_key = value.decode("latin-1")
        elif name == b"authorization" and authorization is None:
            authorization = value.decode("latin-1")
    client = scope.get("client")
    return Credentials(api_key or _bearer_credentials(authorization), client[0] if client else "unknown")


def _bearer_credentials(authorization: str | None) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` value, split as ``fastapi.security.HTTPBearer`` does."""
    if not authorization:
        return None
    scheme, _, token = authorization.partition(" ")
    token = token.strip()
    return token if scheme.lower() == "bearer" and token else None


class Caller(NamedTuple):
    """Who made a request: their verified key, or None for an anonymous caller."""

    key: ApiKey | None
    address: str


def required_role(method: str, path: str, *, require_keys_for_reads: bool) -> Role | None:
    """The least role a request needs by its method and route path; None when anyone may make it."""
    if method.upper() not in READ_METHODS:
        return Role.WRITE
    if not require_keys_for_reads or path in OPEN_READ_PATHS:
        return None
    return Role.READ


def check_role(caller: Caller, required: Role | None) -> None:
    """Raise 401 without a key and 403 with a key whose role is below ``required``."""
    refusal = _role_refusal(caller, required)
    if refusal is not None:
        raise refusal


def _role_refusal(caller: Caller, required: Role | None) -> HTTPException | None:
    """The 401 (no key) or 403 (a key whose role is below ``required``) for ``caller``, or None if they may."""
    if required is None:
        return None
    if caller.key is None:
        return HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            f"this request needs an API key with role {required.value!r} or above; send it as "
            f"'{API_KEY_HEADER}: <secret>' or 'Authorization: Bearer <secret>'",
            headers=CHALLENGE,
        )
    if not caller.key.role.covers(required):
        return HTTPException(
            status.HTTP_403_FORBIDDEN,
            f"API key {caller.key.key_id} ({caller.key.name!r}) has role {caller.key.role.value!r}; "
            f"this request needs {required.value!r} or above",
        )
    return None


class Verdict(NamedTuple):
    """What the access rules decide about a request from memory: the bucket to charge, then let in or refuse.

    :meth:`AccessPolicy.settle` carries it out.
    """

    caller: Caller
    bucket: str
    """The rate-limit bucket the request is charged to: ``key:<key id>`` or ``address:<address>``."""
    refusal: HTTPException | None
    """The 401 or 403 to answer (once charged), or None to let ``caller`` in."""


@dataclass(frozen=True, slots=True)
class _Verified:
    """A key whose secret was verified: the secret's SHA-256, the key's row and when that row was read."""

    digest: bytes
    key: ApiKey
    read_at: float
    """Clock time (s) just before the key's row was read."""


class AccessPolicy:
    """The app's access rules and their state: the rate limiter and keys already verified.

    Verifying a secret costs a scrypt hash (tens of milliseconds), so a verified secret's SHA-256 is remembered
    per key id, and concurrent first requests with the same key wait for one verification. A remembered key is
    trusted for reads for ``recheck_s`` after its row was read; then one request reads the row again, so a key
    revoked elsewhere (``aisle keys revoke``, another API process) stops reading within ``recheck_s``.
    Requests that change something always read the key's row, so a revoked key changes nothing from that
    moment; a key revoked through this app stops at once. Hashing an unverified secret is charged to the
    caller's address, so guessing keys is rate limited too.

    Parameters
    ----------
    require_keys_for_reads : bool
        Whether reads need a ``read`` key too (writes always need a ``write`` key).
    rate_limit_per_s : float or None
        Requests per second allowed per key (anonymous callers: per address); None: no limit.
    rate_limit_burst : int
        Requests allowed at once after a quiet spell.
    recheck_s : float
        Seconds a verified key is trusted for reads before its row is read again (>= 0).
    clock : callable, optional
        Monotonic seconds, for key rechecks and the rate limiter; tests pass a fake one.
    """

    def __init__(self, *, require_keys_for_reads: bool, rate_limit_per_s: float | None,
                 rate_limit_burst: int, recheck_s: float = 1.0, clock: Callable[[], float] = time.monotonic) -> None:
        if not (math.isfinite(recheck_s) and recheck_s >= 0):
            raise ApiConfigError(f"key recheck interval must be a number of seconds >= 0, not {recheck_s}")
        self.require_keys_for_reads = require_keys_for_reads
        self.limiter = (None if rate_limit_per_s is None
                        else TokenBucketLimiter(rate_per_s=rate_limit_per_s, burst=rate_limit_burst, clock=clock))
        self.recheck_s = recheck_s
        self._clock = clock
        self._verified: dict[str, _Verified] = {}
        self._stripes = [threading.Lock() for _ in range(_LOCK_STRIPES)]
        self._hashed = 0

    @property
    def secrets_hashed(self) -> int:
        """Secrets verified with scrypt so far (each costs tens of milliseconds of CPU)."""
        return self._hashed

    def charge(self, bucket: str) -> None:
        """Take one request from ``bucket``; 429 with Retry-After when it is empty."""
        if self.limiter is None:
            return
        wait_s = self.limiter.take(bucket)
        if wait_s > 0:
            raise HTTPException(
                status.HTTP_429_TOO_MANY_REQUESTS,
                f"rate limit of {self.limiter.rate_per_s:g} requests/s (burst {self.limiter.burst}) exceeded; "
                f"retry in {wait_s:.2f} s",
                headers={"Retry-After": str(max(1, math.ceil(wait_s)))},
            )

    def forget(self, key_id: str) -> None:
        """Stop trusting key ``key_id`` from memory (it was just revoked): its next request reads its row."""
        self._verified.pop(key_id, None)

    def remembered(self, secret: str) -> ApiKey | None:
        """The key of ``secret`` if it was verified less than ``recheck_s`` ago, else None; reads no database.

        Charges nothing: charge ``key:<key id>`` for a request it lets through (:meth:`charge`).
        """
        return self._remembered(secret, parse_key_id(secret))

    def _remembered(self, secret: str, key_id: str | None) -> ApiKey | None:
        known = None if key_id is None else self._verified.get(key_id)
        if (known is None or self._clock() - known.read_at > self.recheck_s
                or not hmac.compare_digest(known.digest, hashlib.sha256(secret.encode()).digest())):
            return None
        return known.key

    def admit(self, store: MapStore, credentials: Credentials, *, method: str, route: str) -> Caller:
        """The caller of a request if it may go on: the one access decision, for every path that answers requests.

        Decides from memory when :meth:`judge` can; otherwise reads the key's row (:meth:`authenticate`; always for
        a request that changes something), so it may block: call it in a worker thread from async code.

        Parameters
        ----------
        store : MapStore
            Where the keys are.
        credentials : Credentials
            The key presented and the client's address (:func:`credentials_of`).
        method : str
            The HTTP method.
        route : str
            The route's path template, e.g. ``/v1/maps/{map_name}/bins/{bin_id}``.

        Raises
        ------
        HTTPException
            401 for no key where one is needed, or a malformed, unknown, revoked or wrong one (with a
            ``WWW-Authenticate`` challenge); 403 for a key whose role is below what the request needs; 429 with
            ``Retry-After`` over the rate limit. Each request is charged to one bucket (an unverified secret is
            also charged to the address, as :meth:`authenticate` says).
        """
        verdict = self.judge(credentials, method=method, route=route)
        if verdict is not None:
            return self.settle(verdict)
        caller = self.authenticate(store, credentials.secret, address=credentials.address,
                                   fresh=method not in READ_METHODS)
        check_role(caller, required_role(method, route, require_keys_for_reads=self.require_keys_for_reads))
        return caller

    def judge(self, credentials: Credentials, *, method: str, route: str) -> Verdict | None:
        """What :meth:`admit` decides, if memory suffices to decide it; None when the key's row must be read.

        Memory suffices without a key, with a malformed one, and for a read with a key verified less than
        ``recheck_s`` ago (:meth:`remembered`). Charges nothing and never blocks: :meth:`settle` the verdict.
        """
        secret, address = credentials
        required = required_role(method, route, require_keys_for_reads=self.require_keys_for_reads)
        if secret is None:
            anonymous = Caller(None, address)
            return Verdict(anonymous, f"address:{address}", _role_refusal(anonymous, required))
        key_id = parse_key_id(secret)
        if key_id is None:
            return Verdict(Caller(None, address), f"address:{address}", _malformed())
        key = self._remembered(secret, key_id) if method in READ_METHODS else None
        if key is None:
            return None
        caller = Caller(key, address)
        return Verdict(caller, f"key:{key.key_id}", _role_refusal(caller, required))

    def settle(self, verdict: Verdict) -> Caller:
        """Carry out ``verdict``: charge its bucket (429 when spent), then refuse (401/403) or let the caller in."""
        self.charge(verdict.bucket)
        if verdict.refusal is not None:
            raise verdict.refusal
        return verdict.caller

    def authenticate(self, store: MapStore, secret: str | None, *, address: str, fresh: bool = False) -> Caller:
        """The caller of a request carrying ``secret`` (None: no key), charged to its rate bucket.

        Reads the key's row unless it was read less than ``recheck_s`` ago (always with ``fresh``), and verifies
        the secret unless it was verified before; one request per key does so at a time, the others then use
        its result. Raises 401 for a malformed, unknown, revoked or wrong key and 429 over the rate limit.
        The detail names the key id at most, never the secret.
        """
        if secret is None:
            self.charge(f"address:{address}")
            return Caller(None, address)
        key_id = self._key_id(secret, address=address)
        digest = hashlib.sha256(secret.encode()).digest()
        with self._stripes[hash(key_id) % _LOCK_STRIPES]:
            known = self._verified.get(key_id)
            if (fresh or known is None or self._clock() - known.read_at > self.recheck_s
                    or not hmac.compare_digest(known.digest, digest)):
                known = self._read_key(store, key_id, secret, digest, address=address, known=known)
        self.charge(f"key:{key_id}")
        return Caller(known.key, address)

    def _key_id(self, secret: str, *, address: str) -> str:
        key_id = parse_key_id(secret)
        if key_id is None:
            self.charge(f"address:{address}")
            raise _malformed()
        return key_id

    def _read_key(self, store: MapStore, key_id: str, secret: str, digest: bytes, *, address: str,
                  known: _Verified | None) -> _Verified:
        """Read the key's row, verify ``secret`` unless ``known`` holds its digest, and remember the result."""
        read_at = self._clock()
        key = get_key(store, key_id=key_id)
        if key is None or not key.active:
            self.forget(key_id)
            self.charge(f"address:{address}")
            state = "unknown" if key is None else "revoked"
            raise HTTPException(status.HTTP_401_UNAUTHORIZED, f"API key {key_id} is {state}", headers=CHALLENGE)
        if known is None or not hmac.compare_digest(known.digest, digest):
            self.charge(f"address:{address}")
            self._hashed += 1
            if verify_key(store, secret=secret) is None:
                raise HTTPException(status.HTTP_401_UNAUTHORIZED, f"wrong secret for API key {key_id}",
                                    headers=CHALLENGE)
        verified = self._verified[key_id] = _Verified(digest, key, read_at)
        return verified


def _malformed() -> HTTPException:
    return HTTPException(status.HTTP_401_UNAUTHORIZED,
                         "malformed API key; keys look like aisle_<12 hex>_<43 characters>", headers=CHALLENGE)
