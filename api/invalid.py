"""The 422 answer to a request that fails validation: what is wrong with which part, and the offending input only
as far as it is short and encodable.

FastAPI's own handler echoes each error's input whole: a non-finite number (``NaN``, ``Infinity`` or ``1e400`` in
a JSON body) then cannot be encoded and the client gets a 500, and a large body comes back whole. A non-finite
number that failed a range check is also called out for what it is, not as out of range.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any, Protocol, TypeVar, cast

from fastapi import HTTPException, Request, status
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ValidationError

MAX_ECHO_CHARS = 200
"""Longest input (as JSON text) an error echoes; longer ones are described, not repeated."""

_RANGE_ERRORS = frozenset({"greater_than", "greater_than_equal", "less_than", "less_than_equal", "multiple_of"})
_NOT_FINITE = "Input should be a finite number"


def _is_non_finite(value: Any) -> bool:
    """Whether ``value`` is a non-finite float, or text that reads as one (``nan``, ``-inf``, ``1e400``)."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            return False
    return isinstance(value, float) and not math.isfinite(value)


def _echo(value: Any) -> Any:
    """``value`` as an error may repeat it: JSON-safe (non-finite floats as text) and at most ``MAX_ECHO_CHARS``."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    text = json.dumps(value, default=str)  # NaN inside containers is written as NaN: its length is what counts
    if len(text) <= MAX_ECHO_CHARS:
        return json.loads(text, parse_constant=str)  # nested NaN/Infinity become the strings "NaN"/"Infinity"
    if isinstance(value, str):
        return value[:MAX_ECHO_CHARS] + "…"
    size = f" of {len(value)} items" if isinstance(value, Mapping | list | tuple) else ""
    return f"<{type(value).__name__}{size}, {len(text)} characters as JSON: not repeated>"


def _error(error: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(error)
    if out.get("type") in _RANGE_ERRORS and _is_non_finite(out.get("input")):
        out.update(type="finite_number", msg=_NOT_FINITE)
        out.pop("ctx", None)
    if "input" in out:
        out["input"] = _echo(out["input"])
    if "ctx" in out:
        out["ctx"] = {name: _echo(value) for name, value in out["ctx"].items()}
    return out


async def invalid_request(_request: Request, exc: Exception) -> JSONResponse:
    """Exception handler for :class:`RequestValidationError`: 422 with FastAPI's ``detail`` list, made safe."""
    detail = [_error(error) for error in cast(RequestValidationError, exc).errors()]
    return JSONResponse({"detail": jsonable_encoder(detail)}, status_code=status.HTTP_422_UNPROCESSABLE_CONTENT)


class _Identified(Protocol):
    @property
    def id(self) -> str: ...


class _BinList(Protocol):
    @property
    def bins(self) -> Iterable[_Identified]: ...


ListT = TypeVar("ListT", bound=BaseModel)


def parse_bin_list(model: type[ListT], body: bytes, what: str) -> ListT:
    """``body`` (JSON) read as ``model``, whose ``bins`` must have unique ids: a 422 naming the faults otherwise
    (validation errors located in the body, or up to ten repeated ids), as a request FastAPI validated would get.
    Lists too big for the event loop are parsed here, off it, rather than by a body parameter."""
    try:
        parsed = model.model_validate_json(body)
    except ValidationError as err:
        raise RequestValidationError([{**error, "loc": ("body", *error["loc"])}
                                      for error in err.errors(include_url=False)]) from err
    repeated = sorted(i for i, n in Counter(item.id for item in cast(_BinList, parsed).bins).items() if n > 1)
    if repeated:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, f"{what} must be unique; repeated: {repeated[:10]}")
    return parsed
