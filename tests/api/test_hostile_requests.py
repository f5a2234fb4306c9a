"""Hostile requests to every operation: a clear 4xx (never a 500), and nothing stored changes.

The operations and their parameters are read from the app's own ``/openapi.json``, so endpoints
added later are covered with nothing to list here:

* every operation that changes something (any method but GET/HEAD/OPTIONS) refuses a request
  without a key (401) and with a read key (403);
* every path and query parameter of every operation is sent malformed ids, injection-looking
  strings, NUL bytes, over-long strings, negative, non-finite and out-of-range numbers and huge
  bounding boxes, with an admin key: the answer is a 4xx with a JSON ``detail`` or, for a free-text
  filter, exactly what a harmless literal that matches nothing gets;
* every number of every documented JSON body is sent as ``NaN``, ``Infinity``, ``-Infinity`` and ``1e400``
  (which Python's JSON parser reads as non-finite floats): a 422 saying the number must be finite;
* afterwards every table holds the same rows as before.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from typing import Any, NamedTuple
from urllib.parse import quote

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from shared.store import MapStore
from shared.store.keys import Role, create_key, list_keys
from tests.api.conftest import ClientFactory
from tests.helpers import NON_FINITE_JSON, number_paths, with_literal

READ_METHODS = {"get", "head", "options"}
METHODS = READ_METHODS | {"put", "post", "delete", "patch"}

INJECTIONS = ["1' OR '1'='1", "'; DROP TABLE revisions; --", "1; SELECT pg_sleep(10)"]
MALFORMED = ["../../../etc/passwd", "nul\x00byte", "x" * 5000, "\u202e\U0001f4a5"]
NUMBERS = ["-1", "99999999999999999999999", "NaN", "-inf", "1e309", "1.5"]
BOXES = ["-1e308,-1e308,1e308,1e308", "nan,0,1,1", "1,1,0,0"]
NO_MATCH = "zz-no-such-thing"
"""A harmless literal that names nothing; a free-text filter must treat hostile strings the same way."""


class Operation(NamedTuple):
    method: str
    path: str
    spec: dict[str, Any]

    @property
    def label(self) -> str:
        return f"{self.method.upper()} {self.path}"

    @property
    def streams(self) -> bool:
        """Whether a success is an endless event stream (read only its head then)."""
        return any("text/event-stream" in response.get("content", {})
                   for response in self.spec["responses"].values())

    def parameters(self, where: str) -> list[dict[str, Any]]:
        return [p for p in self.spec.get("parameters", []) if p["in"] == where]


def _operations(spec: dict[str, Any]) -> list[Operation]:
    return [Operation(method, path, operation) for path, item in spec["paths"].items()
            for method, operation in item.items() if method in METHODS]


def _example(parameter: dict[str, Any]) -> Any:
    """A parameter's documented example (every path parameter has one, see test_openapi_completeness)."""
    examples = parameter.get("examples") or parameter.get("schema", {}).get("examples") or ["x"]
    return examples[0] if isinstance(examples, list) else next(iter(examples.values()))["value"]


def _url(operation: Operation, **path_values: Any) -> str:
    """The operation's path with its documented examples, or ``path_values``, filled in (percent-encoded)."""
    url = operation.path
    for parameter in operation.parameters("path"):
        value = path_values.get(parameter["name"], _example(parameter))
        url = url.replace(f"{{{parameter['name']}}}", quote(str(value), safe=""))
    return url


def _scalar_schema(parameter: dict[str, Any]) -> dict[str, Any]:
    """The parameter's schema without the ``null`` of an optional one (and the items of a list)."""
    schema = parameter.get("schema", {})
    choices = [choice for choice in schema.get("anyOf", [schema]) if choice.get("type") != "null"]
    schema = choices[0] if choices else {}
    return schema.get("items", schema) if schema.get("type") == "array" else schema


def _legit_number(value: str, schema: dict[str, Any]) -> bool:
    """Whether ``value`` is a finite number the numeric ``schema`` accepts (so not hostile for it)."""
    try:
        number: float = int(value) if schema.get("type") == "integer" else float(value)
    except ValueError:
        return False
    return (math.isfinite(number)
            and number >= schema.get("minimum", -math.inf) and number <= schema.get("maximum", math.inf)
            and number > schema.get("exclusiveMinimum", -math.inf)
            and number < schema.get("exclusiveMaximum", math.inf))


def _body(spec: dict[str, Any], operation: Operation) -> Any:
    """The request body's documented example, else an empty object."""
    content = operation.spec.get("requestBody", {}).get("content", {}).get("application/json")
    if content is None:
        return None
    schema = content.get("schema", {})
    if "$ref" in schema:
        schema = spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[-1]]
    return (schema.get("examples") or [{}])[0]


def _snapshot(store: MapStore) -> dict[str, Any]:
    """Row count and largest id of every table, and the keys, revisions and live features themselves."""
    inspector = sa.inspect(store.engine)
    counts: dict[str, Any] = {}
    with store.engine.connect() as connection:
        for name in sorted(inspector.get_table_names()):
            table = sa.Table(name, sa.MetaData(), autoload_with=connection)
            counts[name] = connection.execute(sa.select(sa.func.count()).select_from(table)).scalar_one()
    maps = {info.name: info.id for info in store.maps()}
    return {
        "tables": counts,
        "keys": list_keys(store, include_revoked=True),
        "revisions": {name: store.revisions(map_id, limit=10_000) for name, map_id in maps.items()},
        "features": {name: store.features(map_id) for name, map_id in maps.items()},
    }


class Sent(NamedTuple):
    status: int
    body: Any


def _send(client: TestClient, operation: Operation, url: str, *, headers: dict[str, str],
          params: dict[str, str] | None = None, body: Any = None) -> Sent:
    """Status and (JSON or raw) body of one request; an event stream is closed after its head."""
    if operation.streams:
        with client.stream(operation.method.upper(), url, params=params, headers=headers) as response:
            if response.headers.get("content-type", "").startswith("text/event-stream"):
                return Sent(response.status_code, None)
            response.read()
    else:
        response = client.request(operation.method.upper(), url, params=params, headers=headers,
                                  json=body if body is not None else None)
    is_json = response.headers.get("content-type", "").startswith("application/json")
    return Sent(response.status_code, response.json() if is_json else response.content)


@pytest.fixture
def secrets(store: MapStore) -> dict[Role, str]:
    return {role: create_key(store, role=role, name=f"{role.value}-client")[1] for role in Role}


@pytest.fixture
def hostile_client(store: MapStore, make_client: ClientFactory, site: dict[str, int]) -> TestClient:
    """The app as deployed on a network (keys needed for reads), without a rate limit so every probe is answered,
    and answering a 500 rather than raising, so the test can report it."""
    return make_client(store, require_keys_for_reads=True, rate_limit_per_s=None, raise_server_exceptions=False)


def test_every_change_needs_a_key_of_the_right_role_and_refusals_change_nothing(
    store: MapStore, hostile_client: TestClient, secrets: dict[Role, str]
) -> None:
    spec = hostile_client.get("/openapi.json").json()
    writes = [operation for operation in _operations(spec) if operation.method not in READ_METHODS]
    before = _snapshot(store)
    wrong: list[str] = []

    for operation in writes:
        body = _body(spec, operation)
        anonymous = _send(hostile_client, operation, _url(operation), headers={}, body=body)
        reader = _send(hostile_client, operation, _url(operation), headers={"X-API-Key": secrets[Role.READ]},
                       body=body)
        if anonymous.status != 401:
            wrong.append(f"{operation.label} without a key: {anonymous.status}, not 401")
        if reader.status != 403:
            wrong.append(f"{operation.label} with a read key: {reader.status}, not 403")

    assert writes, "the API has no operation that changes anything"
    assert not wrong, "\n".join(wrong)
    assert _snapshot(store) == before


def _probes(operation: Operation) -> Iterator[tuple[dict[str, Any], str]]:
    """(parameter, hostile value) for every path and query parameter of ``operation``.

    Reads get every value everywhere. Writes get only values no parameter of the kind may take
    (numbers out of range or not finite, malformed or injection-looking text), as a value a write
    accepts would change the map.
    """
    for parameter in operation.parameters("path") + operation.parameters("query"):
        if operation.method in READ_METHODS:
            values = INJECTIONS + MALFORMED + NUMBERS + BOXES
        elif _scalar_schema(parameter).get("type") in ("integer", "number"):
            values = [value for value in NUMBERS if not _legit_number(value, _scalar_schema(parameter))]
        else:
            values = INJECTIONS + MALFORMED
        for value in values:
            yield parameter, value


def _judge(operation: Operation, parameter: dict[str, Any], value: str, sent: Sent,
           baseline: Sent | None) -> str | None:
    """What is wrong with the answer ``sent`` to a hostile value, or None.

    ``baseline`` is what a read answers to the harmless :data:`NO_MATCH` in the same place.
    """
    what = f"{operation.label} {parameter['in']} {parameter['name']}={value[:40]!r}"
    schema = _scalar_schema(parameter)
    if sent.status >= 500:
        return f"{what}: {sent.status} {sent.body!r:.200}"
    if 400 <= sent.status < 500:
        detail = sent.body.get("detail") if isinstance(sent.body, dict) else None
        return None if detail else f"{what}: {sent.status} without a JSON detail: {sent.body!r:.200}"
    if schema.get("type") in ("integer", "number"):
        return None if _legit_number(value, schema) else f"{what}: {sent.status}, accepted as a number"
    if baseline is None:
        return f"{what}: {sent.status}; a write took a hostile value"
    if sent != baseline:
        return (f"{what}: {sent.status}, not what the harmless {NO_MATCH!r} gets ({baseline.status}); "
                "a hostile value must be refused or mean nothing")
    return None


def test_hostile_parameters_get_a_clear_4xx_and_change_nothing(
    store: MapStore, hostile_client: TestClient, secrets: dict[Role, str]
) -> None:
    spec = hostile_client.get("/openapi.json").json()
    admin = {"X-API-Key": secrets[Role.ADMIN]}
    before = _snapshot(store)
    wrong: list[str] = []
    probed = 0

    for operation in _operations(spec):
        body = _body(spec, operation)

        def send(parameter: dict[str, Any], literal: str, *, operation: Operation = operation,
                 body: Any = body) -> Sent:
            name = parameter["name"]
            url = _url(operation, **{name: literal}) if parameter["in"] == "path" else _url(operation)
            params = {name: literal} if parameter["in"] == "query" else None
            return _send(hostile_client, operation, url, headers=admin, params=params, body=body)

        baselines: dict[str, Sent] = {}
        for parameter, value in _probes(operation):
            baseline = None
            if operation.method in READ_METHODS:
                baseline = baselines.setdefault(parameter["name"], send(parameter, NO_MATCH))
            problem = _judge(operation, parameter, value, send(parameter, value), baseline)
            probed += 1
            if problem is not None:
                wrong.append(problem)

    assert probed > 100
    assert not wrong, f"{len(wrong)} of {probed} hostile requests answered badly:\n" + "\n".join(wrong[:60])
    assert _snapshot(store) == before


def test_non_finite_numbers_in_a_json_body_get_a_clear_422_and_change_nothing(
    store: MapStore, hostile_client: TestClient, secrets: dict[Role, str]
) -> None:
    spec = hostile_client.get("/openapi.json").json()
    admin = {"X-API-Key": secrets[Role.ADMIN], "Content-Type": "application/json"}
    before = _snapshot(store)
    wrong: list[str] = []
    probed = 0

    for operation in _operations(spec):
        body = _body(spec, operation)
        for path in number_paths(body) if body is not None else ():
            for literal in NON_FINITE_JSON:
                probed += 1
                response = hostile_client.request(operation.method.upper(), _url(operation), headers=admin,
                                                  content=with_literal(body, path, literal))
                what = f"{operation.label} with {'.'.join(map(str, path))} = {literal}"
                detail = response.json().get("detail") if response.status_code == 422 else None
                if response.status_code != 422 or not detail:
                    wrong.append(f"{what}: {response.status_code} {response.text[:200]!r}")
                elif "finite" not in json.dumps(detail):
                    wrong.append(f"{what}: the detail does not say the number must be finite: {detail!r:.300}")

    assert probed, "no documented request body has a number"
    assert not wrong, "\n".join(wrong)
    assert _snapshot(store) == before


@pytest.mark.parametrize("value", ["nan", "inf", "-Infinity"])
def test_a_non_finite_coordinate_is_called_not_finite(hostile_client: TestClient, secrets: dict[Role, str],
                                                      value: str) -> None:
    response = hostile_client.get("/v1/maps/site/semantics", params={"x": value, "y": "1"},
                                  headers={"X-API-Key": secrets[Role.READ]})
    assert response.status_code == 422
    assert "finite" in response.text and "less than" not in response.text
