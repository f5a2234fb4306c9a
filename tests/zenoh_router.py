"""A zenoh router as its own process, as the compose file's ``eclipse/zenoh`` container runs one.

``python -m tests.zenoh_router tcp/127.0.0.1:PORT`` listens there (multicast scouting off) until SIGINT or SIGTERM.
"""

from __future__ import annotations

import signal
import sys
import threading

from shared.bus import Bus
from shared.settings import ZenohSettings


def main(endpoint: str) -> None:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with Bus.open(ZenohSettings(mode="router", listen=[endpoint]), domain_id=0):
        stop.wait()


if __name__ == "__main__":
    main(sys.argv[1])
