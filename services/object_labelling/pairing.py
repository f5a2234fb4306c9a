"""Pair colour and depth frames of each robot by stamp.

The two streams of an RGB-D camera arrive on separate topics through queues that drop the oldest
frames independently, so a frame may lose its partner. :class:`FramePairer` keeps the newest few
frames of each stream per robot, pairs a frame with the other stream's frame of the same stamp
(within a tolerance) as soon as both are there, and holds only the newest complete pair per robot:
the labeller always gets the latest frame, older pairs are counted as skipped.
"""

from __future__ import annotations

import collections
import enum
from dataclasses import dataclass, field
from typing import Generic, NamedTuple, TypeVar

from services.object_labelling.errors import ObjectLabellingError

T = TypeVar("T")


class Stream(enum.Enum):
    """The two streams of an RGB-D camera."""

    COLOUR = "colour"
    DEPTH = "depth"


class FramePair(NamedTuple, Generic[T]):
    """A colour and a depth frame of one robot; ``stamp_ns`` is the colour frame's stamp."""

    namespace: str
    stamp_ns: int
    colour: T
    depth: T


@dataclass
class _Robot(Generic[T]):
    frames: dict[Stream, collections.deque[tuple[int, T]]]
    ready: FramePair[T] | None = None


@dataclass
class FramePairer(Generic[T]):
    """Stamp-matched colour/depth pairs per robot namespace.

    Parameters
    ----------
    tolerance_ns
        Largest stamp difference of a pair, nanoseconds (0: exact stamps only).
    keep_frames
        Unpaired frames kept per stream and robot while waiting for a partner.
    """

    tolerance_ns: int = 5_000_000
    keep_frames: int = 3
    skipped: int = 0
    """Complete pairs replaced by a newer one before they were taken."""
    _robots: dict[str, _Robot[T]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if self.tolerance_ns < 0 or self.keep_frames < 1:
            raise ObjectLabellingError(
                f"need tolerance_ns >= 0 and keep_frames >= 1, got {self.tolerance_ns}, {self.keep_frames}"
            )

    def add(self, namespace: str, stream: Stream, stamp_ns: int, frame: T) -> bool:
        """Add a frame; True when it completed a pair (now the robot's newest, see :meth:`take`)."""
        robot = self._robots.get(namespace)
        if robot is None:
            robot = self._robots[namespace] = _Robot(
                {s: collections.deque(maxlen=self.keep_frames) for s in Stream}
            )
        other = robot.frames[Stream.DEPTH if stream is Stream.COLOUR else Stream.COLOUR]
        match = min(
            (i for i, (stamp, _) in enumerate(other) if abs(stamp - stamp_ns) <= self.tolerance_ns),
            key=lambda i: abs(other[i][0] - stamp_ns),
            default=None,
        )
        if match is None:
            robot.frames[stream].append((stamp_ns, frame))
            return False
        partner_stamp, partner = other[match]
        for _ in range(match + 1):  # the partner and every older frame of that stream
            other.popleft()
        mine = robot.frames[stream]
        while mine and mine[0][0] <= stamp_ns:
            mine.popleft()
        colour, depth = (frame, partner) if stream is Stream.COLOUR else (partner, frame)
        colour_stamp = stamp_ns if stream is Stream.COLOUR else partner_stamp
        if robot.ready is not None:
            if robot.ready.stamp_ns > colour_stamp:  # a late pair older than the one waiting
                self.skipped += 1
                return False
            self.skipped += 1
        robot.ready = FramePair(namespace, colour_stamp, colour, depth)
        return True

    def take(self) -> list[FramePair[T]]:
        """The newest complete pair of every robot that has one (each pair is handed out once)."""
        pairs = [robot.ready for robot in self._robots.values() if robot.ready is not None]
        for robot in self._robots.values():
            robot.ready = None
        return pairs
