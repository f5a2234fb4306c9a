"""API keys: list, create and revoke them (admin keys only)."""

from __future__ import annotations

import datetime as dt
import logging
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Path, Query, status
from pydantic import BaseModel, Field

from api.deps import AdminDep, ContextDep, StoreDep, require_admin
from api.models import COMMON_ERRORS, UNPROCESSABLE, ErrorOut, Responses, example_config, not_found
from shared.store.keys import KEY_ID_PATTERN, MAX_NAME_LENGTH, ApiKey, Role, create_key, get_key, list_keys, revoke_key

log = logging.getLogger(__name__)

router = APIRouter(prefix="/v1/keys", tags=["keys"], dependencies=[Depends(require_admin)])

_AUTH: Responses = {
    **COMMON_ERRORS,
    status.HTTP_403_FORBIDDEN: {"model": ErrorOut, "description": "The key is not an admin key."},
    **UNPROCESSABLE,
}

KeyIdPath = Annotated[str, Path(description="Public id of the key (12 hex characters).",
                                pattern=f"^{KEY_ID_PATTERN.pattern}$", examples=["3f9c2a71b0de"])]

_KEY_EXAMPLE = {"key_id": "3f9c2a71b0de", "name": "wms", "role": "read", "created_at": "2025-03-04T10:15:00Z",
                "revoked_at": None}


class KeyIn(BaseModel):
    name: str = Field(min_length=1, max_length=MAX_NAME_LENGTH, pattern=r"^[A-Za-z0-9 ._@:-]+$",
                      description="Who the key is for, e.g. `wms`.")
    role: Role = Field(description="read < write < admin.")

    model_config = example_config(name="wms", role="read")


class KeyOut(BaseModel):
    key_id: str = Field(description="Public id: the 12 hex characters after `aisle_` in the secret.")
    name: str
    role: Role
    created_at: dt.datetime
    revoked_at: dt.datetime | None

    model_config = example_config(**_KEY_EXAMPLE)


class KeyCreated(KeyOut):
    secret: str = Field(description="The key itself; shown only in this response, store it now.")

    model_config = example_config(**_KEY_EXAMPLE,
                                  secret="aisle_3f9c2a71b0de_q3X9vJ0kz7WcN1bEw5Hf2uYtPaLr8sDgMiKo4nQe6Zx")


def key_out(key: ApiKey) -> KeyOut:
    return KeyOut(key_id=key.key_id, name=key.name, role=key.role, created_at=key.created_at,
                  revoked_at=key.revoked_at)


@router.get("", summary="List keys", responses=_AUTH)
def get_keys(
    store: StoreDep,
    include_revoked: Annotated[bool, Query(description="Also list revoked keys.", examples=[True])] = False,
) -> list[KeyOut]:
    """Every key's public id, name, role and dates (never a secret), oldest first."""
    return [key_out(key) for key in list_keys(store, include_revoked=include_revoked)]


@router.post("", summary="Create a key", status_code=status.HTTP_201_CREATED, responses=_AUTH)
def post_key(body: KeyIn, store: StoreDep, caller: AdminDep) -> KeyCreated:
    """A new key; the response holds its secret, which the server does not keep."""
    key_id, secret = create_key(store, role=body.role, name=body.name)
    log.info("API key %s (%s, %r) created by %s", key_id, body.role.value, body.name,
             caller.key.key_id if caller.key else "?")
    created = get_key(store, key_id=key_id)
    assert created is not None  # written in the line above
    return KeyCreated(**key_out(created).model_dump(), secret=secret)


@router.delete(
    "/{key_id}",
    summary="Revoke a key",
    responses={**_AUTH, **not_found("No such key."),
               status.HTTP_409_CONFLICT: {"model": ErrorOut, "description": "The last active admin key."}},
)
def delete_key(key_id: KeyIdPath, store: StoreDep, caller: AdminDep, context: ContextDep) -> KeyOut:
    """Revoke a key at once; it stays listed with ``?include_revoked=true``. The last admin key cannot go."""
    active = list_keys(store)
    target = next((key for key in active if key.key_id == key_id), None)
    admins = [key for key in active if key.role is Role.ADMIN]
    if target is not None and target.role is Role.ADMIN and len(admins) == 1:
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"key {key_id} is the last active admin key; create another admin key first")
    revoked = revoke_key(store, key_id=key_id)
    if revoked is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no API key {key_id}")
    context.access.forget(key_id)
    log.info("API key %s revoked by %s", key_id, caller.key.key_id if caller.key else "?")
    return key_out(revoked)
