"""Is the service whole: database reachable, bus up, stage workers alive."""

from __future__ import annotations

import datetime as dt

import sqlalchemy as sa
from fastapi import APIRouter, Response, status

from api.deps import ContextDep, SettingsDep
from api.models import COMMON_ERRORS, BusHealth, DatabaseHealth, HealthOut, WorkerHealth
from shared.store import MapStore, StoreUnavailableError, WorkerInfo

router = APIRouter(prefix="/v1/health", tags=["health"])

HEARTBEAT_TIMEOUT_S = 15.0
"""Without a bus, a worker is alive if its last stored heartbeat (every ~5 s) is younger than this."""

LIVELINESS_TIMEOUT_S = 0.5
"""How long to wait for liveliness replies on the bus."""


def _database(store: MapStore) -> tuple[DatabaseHealth, list[WorkerInfo]]:
    url = sa.make_url(store.url).render_as_string(hide_password=True)
    try:
        store.ping()
        workers = store.workers()
    except StoreUnavailableError as err:
        return DatabaseHealth(ok=False, detail=str(err), url=url), []
    return DatabaseHealth(ok=True, detail="reachable", url=url), workers


@router.get(
    "",
    summary="Service health",
    responses={
        **{code: COMMON_ERRORS[code] for code in (status.HTTP_401_UNAUTHORIZED, status.HTTP_429_TOO_MANY_REQUESTS)},
        status.HTTP_503_SERVICE_UNAVAILABLE: {"model": HealthOut, "description": "Degraded (same body)."},
    },
)
def health(context: ContextDep, settings: SettingsDep, response: Response) -> HealthOut:
    """Database, bus and worker health; HTTP 503 (same body) when anything is degraded.

    A worker is alive when its liveliness token is seen on the bus or, when the API runs
    without a bus, when its stored heartbeat is younger than 15 s.
    """
    database, stored = _database(context.store)
    heartbeats = {info.name: info for info in stored}
    if context.bus is None:
        bus = BusHealth(ok=True, mode="none", detail="no bus; worker liveness from database heartbeats",
                        counters={})
        now = dt.datetime.now(dt.UTC)
        alive = {name for name, info in heartbeats.items()
                 if (now - info.heartbeat_at).total_seconds() < HEARTBEAT_TIMEOUT_S}
    else:
        try:
            alive = set(context.bus.alive_workers(LIVELINESS_TIMEOUT_S))
        except Exception as err:  # any failure of the bus must show as degraded, not as a 500
            bus = BusHealth(ok=False, mode=settings.zenoh.mode, detail=f"liveliness query failed: {err}",
                            counters=context.bus.counters.snapshot())
            alive = set()
        else:
            bus = BusHealth(ok=True, mode=settings.zenoh.mode, detail=f"{len(alive)} worker(s) seen",
                            counters=context.bus.counters.snapshot())
    names = sorted(heartbeats.keys() | alive | set(context.expected_workers))
    workers = [
        WorkerHealth(
            name=name,
            alive=name in alive,
            heartbeat_at=heartbeats[name].heartbeat_at if name in heartbeats else None,
            counters=dict(heartbeats[name].counters) if name in heartbeats else {},
        )
        for name in names
    ]
    missing = [name for name in context.expected_workers if name not in alive]
    degraded = not database.ok or not bus.ok or bool(missing)
    if degraded:
        response.status_code = status.HTTP_503_SERVICE_UNAVAILABLE
    return HealthOut(status="degraded" if degraded else "ok", database=database, bus=bus, workers=workers,
                     missing_workers=missing)
