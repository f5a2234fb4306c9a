"""Replay, recording and import of logged sensor traffic (rosbag2, CARMEN)."""

from services.replay.carmen import CarmenError, CarmenImport, import_carmen
from services.replay.record import RecordStats, record
from services.replay.replay import ReplayError, ReplayStats, replay_bag

__all__ = [
    "CarmenError",
    "CarmenImport",
    "RecordStats",
    "ReplayError",
    "ReplayStats",
    "import_carmen",
    "record",
    "replay_bag",
]
