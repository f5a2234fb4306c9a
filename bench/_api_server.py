"""The API as ``aisle serve`` builds it, as a uvicorn app factory, so ``bench_api_load.py --workers N`` can run
it in several processes: ``uvicorn --factory bench._api_server:app --workers N``.

Built from the same ``AISLE_*`` settings as ``aisle serve``, without the zenoh bus (the health check then
reads worker liveness from stored heartbeats; nothing the bench asks for needs the bus).
"""

from __future__ import annotations

from fastapi import FastAPI

from api import create_app
from services.runtime import open_store
from shared.settings import get_settings


def app() -> FastAPI:
    """A new app over the store named by the settings (one per worker process)."""
    settings = get_settings()
    return create_app(store=open_store(settings), settings=settings, require_keys_for_reads=settings.reads_need_key,
                      rate_limit_per_s=settings.api_rate_limit_per_s, rate_limit_burst=settings.api_rate_limit_burst,
                      cors_origins=settings.api_cors_origins, event_poll_s=settings.api_event_poll_s,
                      event_heartbeat_s=settings.api_event_heartbeat_s, live_staleness_s=settings.api_live_staleness_s,
                      key_recheck_s=settings.api_key_recheck_s, gzip_min_bytes=settings.api_gzip_min_bytes)
