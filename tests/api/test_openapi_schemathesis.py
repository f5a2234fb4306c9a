"""Schemathesis over the whole OpenAPI schema: no 500s, and every response as the schema says.

The operations come from the app's own ``/openapi.json`` at run time, so an endpoint added later is
covered with nothing to list here. Every request carries an admin key, so write endpoints are
exercised too, over the real store (SQLite, and PostgreSQL when configured) holding the sample map
of ``site`` plus features named like the schema's examples. Each operation gets its documented
examples, then schema-valid (positive) and schema-breaking (negative) requests, a bounded number
of each, derandomized so every run sends the same requests. Schemathesis never writes a non-finite number into
JSON, so operations with a JSON body also get schema-valid bodies with one number (or, without numbers, the whole
body) written as ``NaN``, ``Infinity``, ``-Infinity`` or ``1e400`` (:func:`_non_finite`).
"""

from __future__ import annotations

from typing import Any

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from schemathesis.checks import not_a_server_error
from schemathesis.core.failures import FailureGroup
from schemathesis.core.result import Err
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from shared.loads import Occupancy, write_scene_revision
from shared.store import Feature, MapStore, RevisionWrite
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory
from tests.helpers import NON_FINITE_JSON, number_paths, with_literal
from tests.loads_data import BAY_1, bay_1_scene, seen

MAX_EXAMPLES = 10
"""Generated requests per operation and generation mode: bounded so the run stays around a minute."""
STREAM_READ_S = 1.0
"""How long an event stream is read before it is cut (it sends events only as revisions arrive); 0.2 s once
cut the first request before its answer began on a loaded CI machine."""
READ_S = 30.0
"""Longest wait for any other response."""

Operation = schemathesis.APIOperation[Any, Any, Any, Any]
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_headers_conformance,
          response_schema_conformance]


@pytest.fixture
def admin_secret(store: MapStore) -> str:
    return create_key(store, role=Role.ADMIN, name="schemathesis")[1]


@pytest.fixture
def example_features(store: MapStore, site: dict[str, int]) -> int:
    """A revision of ``site`` with a bin keyed as the schema's examples are, so examples find something, and what
    the robots saw in it (its state and its bay's scene)."""
    ring = [[40.6, 17.1], [41.8, 17.1], [41.8, 18.1], [40.6, 18.1], [40.6, 17.1]]
    bin_03_014 = Feature("bin", "03-014", {"type": "Polygon", "coordinates": [ring]},
                         {"id": "03-014", "aisle": 3, "bay": 14, "level": None, "access_pose": [41.2, 15.6, 1.5708],
                          "row": "r0-006", "back_row": "r0-007", "centre": [41.2, 17.6]}, 0.92)
    map_id = store.ensure_map("site").id
    store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": [bin_03_014]}))
    written = write_scene_revision(store, map_id, [bay_1_scene()],
                                   [seen("03-014", Occupancy.OCCUPIED, views=3, objects=("p1", "l1"), bay=BAY_1)])
    assert written.revision is not None
    return written.revision.id


@pytest.fixture
def api_schema(store: MapStore, make_client: ClientFactory, example_features: int,
               admin_secret: str) -> schemathesis.BaseSchema:
    """The app's schema, loaded from the app itself, with keys required for reads and no rate limit."""
    client = make_client(store, require_keys_for_reads=True, rate_limit_per_s=None)
    config = schemathesis.Config.from_dict({"headers": {"X-API-Key": admin_secret}, "max-stream-events": 1})
    return schemathesis.openapi.from_asgi("/openapi.json", client.app, config=config)


def _is_stream(operation: Operation) -> bool:
    """Whether the operation answers with an endless event stream (``text/event-stream``)."""
    return any("text/event-stream" in response.get("content", {})
               for response in operation.definition.raw.get("responses", {}).values())


def _non_finite(operation: Operation) -> st.SearchStrategy[schemathesis.Case[Any]]:
    """Schema-valid requests of ``operation`` whose JSON body has one number, or is itself, non-finite."""

    @st.composite
    def cases(draw: st.DrawFn) -> schemathesis.Case[Any]:
        case = draw(operation.as_strategy(schemathesis.GenerationMode.POSITIVE))
        path = draw(st.sampled_from([*number_paths(case.body), ()]))
        case.body = with_literal(case.body, path, draw(st.sampled_from(NON_FINITE_JSON)))
        return case

    return cases()


def _has_json_body(operation: Operation) -> bool:
    return any(body.media_type == "application/json" for body in operation.body)


def _run(strategy: st.SearchStrategy[schemathesis.Case[Any]], secret: str, *, max_examples: int,
         stream: bool) -> None:
    timeout_s = STREAM_READ_S if stream else READ_S

    @given(case=strategy)
    @settings(max_examples=max_examples, derandomize=True, database=None, deadline=None,
              suppress_health_check=list(HealthCheck), report_multiple_bugs=False)
    def check(case: schemathesis.Case[Any]) -> None:
        case.call_and_validate(headers={"X-API-Key": secret}, checks=CHECKS, timeout=timeout_s)

    check()


def _failure(operation: Operation, secret: str) -> str | None:
    """The first failure of ``operation`` with its documented examples, then positive, then negative requests."""
    stream = _is_stream(operation)
    strategies = [(example, 1) for example in operation.get_strategies_from_examples()]
    strategies += [(operation.as_strategy(mode), MAX_EXAMPLES)
                   for mode in (schemathesis.GenerationMode.POSITIVE, schemathesis.GenerationMode.NEGATIVE)]
    if _has_json_body(operation):
        strategies.append((_non_finite(operation), MAX_EXAMPLES))
    for strategy, max_examples in strategies:
        try:
            _run(strategy, secret, max_examples=max_examples, stream=stream)
        except (Exception, FailureGroup) as err:
            return str(err)
    return None


def test_every_operation_answers_as_documented_and_never_500(api_schema: schemathesis.BaseSchema,
                                                              admin_secret: str) -> None:
    operations: list[Operation] = []
    failed: dict[str, str] = {}
    for result in api_schema.get_all_operations():
        if isinstance(result, Err):
            failed[str(result.err().label)] = f"invalid operation in the OpenAPI schema: {result.err()}"
        else:
            operations.append(result.ok())
    for operation in operations:
        message = _failure(operation, admin_secret)
        if message is not None:
            failed[operation.label] = message

    assert len(operations) >= 10
    assert not failed, "\n\n".join(f"{label}:\n{message}" for label, message in failed.items())
