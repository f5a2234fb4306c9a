"""Write simulated messages to a rosbag2 file (MCAP storage)."""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer

from services.simulator.errors import SimulatorError
from services.simulator.stream import Output, topic_name
from shared.messages import TYPESTORE

log = logging.getLogger(__name__)


def write_bag(outputs: Iterable[Output], path: Path) -> Counter[str]:
    """Write ``outputs`` (in stamp order) to a new MCAP rosbag2 directory ``path``; messages per topic.

    Each message is written at its header stamp, so the bag's time is the simulation's time.
    """
    path = Path(path)
    if path.exists():
        raise SimulatorError(f"{path} exists already; not overwriting it")
    written: Counter[str] = Counter()
    connections: dict[tuple[str, str], Connection] = {}
    with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP) as writer:
        for output in outputs:
            name = topic_name(output)
            connection = connections.get((name, output.msgtype))
            if connection is None:
                connection = writer.add_connection(name, output.msgtype, typestore=TYPESTORE)
                connections[name, output.msgtype] = connection
            writer.write(connection, output.stamp_ns, bytes(TYPESTORE.serialize_cdr(output.message, output.msgtype)))
            written[name] += 1
    log.info("wrote %d messages on %d topics to %s", written.total(), len(written), path)
    return written
