"""/openapi.json documents every operation fully: what it does, how it fails, and examples to copy.

The operations are read from the schema the app serves, so endpoints added later are held to the same rules.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from fastapi.testclient import TestClient

Spec = dict[str, Any]
METHODS = {"get", "put", "post", "delete", "patch", "head", "options"}


def _operations(spec: Spec) -> Iterator[tuple[str, Spec]]:
    for path, item in spec["paths"].items():
        for method, operation in item.items():
            if method in METHODS:
                yield f"{method.upper()} {path}", operation


def _has_example(spec: Spec, schema: Spec) -> bool:
    """Whether ``schema`` (following references and array items) carries an example."""
    if "examples" in schema or "example" in schema:
        return True
    if "$ref" in schema:
        return _has_example(spec, spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[-1]])
    return "items" in schema and _has_example(spec, schema["items"])


def _json_bodies(operation: Spec) -> Iterator[tuple[str, Spec]]:
    """(where, media type object) of the operation's JSON request body and JSON success responses."""
    for media_type, content in operation.get("requestBody", {}).get("content", {}).items():
        if media_type.endswith("json"):
            yield f"request {media_type}", content
    for code, response in operation["responses"].items():
        for media_type, content in response.get("content", {}).items():
            if code.startswith("2") and media_type.endswith("json"):
                yield f"{code} {media_type}", content


def test_every_operation_has_a_summary_a_description_errors_and_described_parameters(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()
    problems: list[str] = []

    for label, operation in _operations(spec):
        if not operation.get("summary"):
            problems.append(f"{label}: no summary")
        if not operation.get("description"):
            problems.append(f"{label}: no description (the route's docstring)")
        if not any(code.startswith("4") for code in operation["responses"]):
            problems.append(f"{label}: no documented 4xx response")
        for parameter in operation.get("parameters", []):
            documented = (parameter.get("description") or parameter.get("examples") or "example" in parameter
                          or parameter.get("schema", {}).get("examples"))
            if not documented:
                problems.append(f"{label}: parameter {parameter['name']!r} has neither description nor example")

    assert len(list(_operations(spec))) >= 10
    assert not problems, "\n".join(problems)


def test_every_json_body_has_an_example(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()

    missing = [f"{label}: {where}" for label, operation in _operations(spec)
               for where, content in _json_bodies(operation)
               if not (content.get("examples") or "example" in content
                       or _has_example(spec, content.get("schema", {})))]

    assert not missing, "no example for:\n" + "\n".join(missing)


def test_errors_are_documented_as_json_with_a_detail(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()

    wrong = [f"{label}: {code} as {sorted(response.get('content', {}))}"
             for label, operation in _operations(spec) for code, response in operation["responses"].items()
             if code.startswith("4") and "application/json" not in response.get("content", {})]

    assert not wrong, "error responses that are not JSON:\n" + "\n".join(wrong)
