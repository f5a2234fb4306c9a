"""Helpers for tests: free ports, real-data paths, waiting on conditions, non-finite numbers in JSON text."""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any, TypeVar

import pytest

T = TypeVar("T")
DATA_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def free_port() -> int:
    """A TCP port on loopback nobody listens on right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def data_path(*parts: str) -> Path:
    """A path in the shared real-data folder; skips the test when it is absent."""
    path = DATA_DIR.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data {path} is not present (it lives beside the checkout in ../shared/data)")
    return path


def wait_for(condition: Callable[[], object], *, timeout_s: float = 10.0, what: str = "condition",
             interval_s: float = 0.02) -> None:
    """Poll ``condition`` every ``interval_s`` until truthy; fail the test after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(interval_s)


NON_FINITE_JSON = ["NaN", "Infinity", "-Infinity", "1e400"]
"""Numbers Python's JSON parser reads as non-finite floats (schemathesis never sends them)."""


def number_paths(value: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """Paths to every number (not a bool) in a JSON document."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from number_paths(item, (*path, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from number_paths(item, (*path, index))
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield path


def with_literal(document: Any, path: tuple[Any, ...], literal: str) -> bytes:
    """``document`` as JSON text with the number at ``path`` written as ``literal`` (``NaN``, ``1e400``...); the
    empty path stands for the whole document."""
    if not path:
        return literal.encode()
    marker = "\u0000hostile\u0000"
    parent = document
    for step in path[:-1]:
        parent = parent[step]
    saved, parent[path[-1]] = parent[path[-1]], marker
    try:
        return json.dumps(document).replace(json.dumps(marker), literal).encode()
    finally:
        parent[path[-1]] = saved


def after_first_of_overlapping_blocks(block: Callable[[], AbstractContextManager[None]], read: Callable[[], T]) -> T:
    """``read()`` inside the second of two overlapping ``block()``s, in two threads, once the first of them (begun
    first) has ended."""
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()

    def first() -> None:
        with block():
            first_in.set()
            second_in.wait(10)
        first_out.set()

    thread = threading.Thread(target=first)
    thread.start()
    first_in.wait(10)
    with block():
        second_in.set()
        first_out.wait(10)
        value = read()
    thread.join()
    return value
