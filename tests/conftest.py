"""Fixtures shared by every test: real zenoh sessions on loopback, real SQLite and PostgreSQL stores."""

from __future__ import annotations

import gc
import os
import shutil
import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest
import sqlalchemy as sa

from shared.bus import Bus
from shared.settings import ZenohSettings
from shared.store import MapStore, schema
from tests.helpers import free_port

POSTGRES_URL_ENV = "AISLE_TEST_POSTGRES_URL"
LONGEST = ("tests/test_wms_end_to_end.py", "tests/test_scaleout.py")
"""The two longest modules (2.6 and 1.7 minutes of the 12.7 of ``make test`` on the 2-core machine, 27 November),
one for each of the two processes from the start: either, started after the other end-to-end modules, could end
the run on its own."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Run the :data:`LONGEST` modules first, then the other end-to-end modules (every test slow), then the modules
    with some slow tests, then the rest; each module keeps its tests' order. ``make test`` hands modules to two
    processes in this order (pytest-xdist, ``--dist loadscope``), so the long runs start early instead of ending
    last, each on its own."""
    def module(item: pytest.Item) -> str:
        return item.nodeid.split("::")[0]

    slow: dict[str, list[bool]] = {}
    for item in items:
        slow.setdefault(module(item), []).append(item.get_closest_marker("slow") is not None)
    weight = {name: 2 if all(marks) else int(any(marks)) for name, marks in slow.items()}
    order = {name: index for index, name in enumerate(slow)}
    first = {name: LONGEST.index(name) if name in LONGEST else len(LONGEST) for name in slow}
    items.sort(key=lambda item: (first[module(item)], -weight[module(item)], order[module(item)]))


@pytest.fixture
def zenoh_listen() -> ZenohSettings:
    """Settings for a peer listening on a free loopback port, scouting off."""
    return ZenohSettings(listen=[f"tcp/127.0.0.1:{free_port()}"])


@pytest.fixture
def bus_pair(zenoh_listen: ZenohSettings) -> Iterator[tuple[Bus, Bus]]:
    """Two connected zenoh sessions: the first listens, the second connects to it."""
    other = ZenohSettings(listen=[], connect=zenoh_listen.listen)
    with ExitStack() as stack:
        first = stack.enter_context(Bus.open(zenoh_listen, domain_id=0))
        second = stack.enter_context(Bus.open(other, domain_id=0))
        yield first, second


def _postgres_url() -> str:
    url = os.environ.get(POSTGRES_URL_ENV)
    if not url:
        pytest.skip(f"PostgreSQL tests need {POSTGRES_URL_ENV}, e.g. postgresql+psycopg://postgres@127.0.0.1/test")
    return url


@contextmanager
def _fresh_schema(base: str) -> Iterator[str]:
    """A URL to a new, empty schema in the PostgreSQL database at ``base``; dropped afterwards."""
    schema_name = f"aisle_test_{uuid.uuid4().hex[:12]}"
    admin = sa.create_engine(base)
    with admin.begin() as connection:
        connection.execute(sa.text(f'CREATE SCHEMA "{schema_name}"'))
    separator = "&" if "?" in base else "?"
    try:
        yield f"{base}{separator}options=-csearch_path%3D{schema_name}"
    finally:
        with admin.begin() as connection:
            connection.execute(sa.text(f'DROP SCHEMA "{schema_name}" CASCADE'))
        admin.dispose()


def _migrated(url: str) -> None:
    map_store = MapStore(url)
    try:
        assert map_store.upgrade() is True, f"{url}: not a fresh database"
    finally:
        map_store.close()


@pytest.fixture
def postgres_url() -> Iterator[str]:
    """A URL to a fresh, empty schema in the test PostgreSQL; dropped afterwards."""
    with _fresh_schema(_postgres_url()) as url:
        yield url


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A database URL per backend: a SQLite file, or a fresh PostgreSQL schema; both empty, not migrated."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'aisle.db'}"
    url: str = request.getfixturevalue("postgres_url")
    return url


@pytest.fixture(scope="session")
def _sqlite_at_head(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A SQLite file migrated to the newest schema once per test process, copied for each test."""
    path = tmp_path_factory.mktemp("schema_at_head") / "aisle.db"
    _migrated(f"sqlite:///{path}")
    assert not path.with_name(f"{path.name}-wal").exists(), "the closed store left a write-ahead log"
    return path


@pytest.fixture(scope="session")
def _postgres_at_head() -> Iterator[tuple[str, sa.Engine]]:
    """A PostgreSQL schema migrated to the newest revision once per test process (each pytest-xdist worker has
    its own), emptied for each test; its URL and an engine on it."""
    with _fresh_schema(_postgres_url()) as url:
        _migrated(url)
        engine = sa.create_engine(url, pool_size=1)
        yield url, engine
        engine.dispose()


@pytest.fixture(params=["sqlite", "postgresql"])
def migrated_store_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A database URL per backend with the newest schema and no rows, as a fresh database after ``upgrade()``.

    The migrations run once per test process (:func:`_sqlite_at_head`, :func:`_postgres_at_head`); each test gets a
    copy of the SQLite file, or the PostgreSQL schema with every table emptied and its ids restarted.
    """
    if request.param == "sqlite":
        path = tmp_path / "aisle.db"
        shutil.copyfile(request.getfixturevalue("_sqlite_at_head"), path)
        return f"sqlite:///{path}"
    url, engine = request.getfixturevalue("_postgres_at_head")
    tables = ", ".join(f'"{table.name}"' for table in schema.metadata.sorted_tables)
    with engine.begin() as connection:
        connection.execute(sa.text(f"TRUNCATE {tables} RESTART IDENTITY CASCADE"))
    return str(url)


@pytest.fixture
def store(migrated_store_url: str) -> Iterator[MapStore]:
    """A migrated map store on each backend."""
    map_store = MapStore(migrated_store_url, layer_history=3)
    yield map_store
    map_store.close()


@pytest.fixture
def collector_on() -> Iterator[None]:
    """CPython's cyclic garbage collector switched on for the test, and back as it was after it."""
    was_enabled = gc.isenabled()
    gc.enable()
    yield
    if not was_enabled:
        gc.disable()
