"""/openapi.json says the unit of every number it serves or takes, and the frame of every position.

Walks every schema of the served OpenAPI document (and every numeric parameter), so fields added later are held to
the same rule: a numeric property (a number, an integer, or a list or tuple of them, nullable or not) needs a
description naming its unit, and a position in metres needs its frame.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

from fastapi.testclient import TestClient

Spec = dict[str, Any]

UNITS = re.compile(r"metre|\bm²|\bm\^2|radian|second|\bms\b|\bns\b|percent|probability|0\.\.1|\bcount\b|bytes|"
                   r"pixel|\bcells?\b|\bid\b|index|\bnumber\b|revision|code|per second",
                   re.IGNORECASE)
"""What counts as naming a unit (identifiers, numbers and counts say what they number or count)."""
LENGTHS = ("distance", "width", "length", "resolution", "tolerance", "area", "height", "z_m", "depth", "spacing",
           "radius", "staleness", "median", "delta", "offset", "extent_m")
"""Property names that are lengths (or differences), not positions: metres without a frame."""
FRAME = re.compile(r"frame", re.IGNORECASE)


def _numeric(schema: Spec) -> bool:
    """Whether a property schema is a number, an integer, or a list/tuple of them (nullable or not)."""
    if schema.get("type") in ("number", "integer"):
        return True
    if "anyOf" in schema:
        return any(_numeric(option) for option in schema["anyOf"] if option.get("type") != "null")
    items = [schema["items"]] if isinstance(schema.get("items"), dict) else []
    return any(_numeric(item) for item in items + schema.get("prefixItems", []))


def _numeric_fields(spec: Spec) -> Iterator[tuple[str, str, Spec]]:
    """(where, name, schema) of every numeric property of every component schema and every numeric parameter."""
    for model, schema in spec["components"]["schemas"].items():
        for name, prop in schema.get("properties", {}).items():
            if _numeric(prop):
                yield model, name, prop
    for path, item in spec["paths"].items():
        for method, operation in item.items():
            for parameter in operation.get("parameters", []) if isinstance(operation, dict) else []:
                if _numeric(parameter.get("schema", {})):
                    yield f"{method.upper()} {path}", parameter["name"], {
                        "description": parameter.get("description") or parameter["schema"].get("description")}


def test_every_numeric_field_names_its_unit_and_every_position_its_frame(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()
    problems: list[str] = []

    fields = list(_numeric_fields(spec))
    for where, name, schema in fields:
        text = schema.get("description") or ""
        if not UNITS.search(text):
            problems.append(f"{where}.{name}: no unit in {text!r}")
        elif re.search(r"metre", text, re.IGNORECASE) and not any(word in name for word in LENGTHS) \
                and not FRAME.search(text):
            problems.append(f"{where}.{name}: a position in metres without its frame: {text!r}")

    assert len(fields) > 50
    assert not problems, f"{len(problems)} numeric fields lack a unit or frame:\n" + "\n".join(problems)
