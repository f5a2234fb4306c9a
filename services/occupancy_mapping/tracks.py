"""Where each robot has been: the poses of its integrated scans over a recent window, thinned in time."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from shared.robots import Robot, TrackPoint
from shared.transforms import Pose2D


@dataclass
class TrackRecorder:
    """The recent track of every robot, from the poses its scans were integrated at.

    Parameters
    ----------
    window_s : float
        How far back a track reaches, seconds of scan time before the robot's newest pose.
    spacing_s : float
        Least time between two kept poses of a track (the newest pose is always kept), seconds.

    Examples
    --------
    >>> tracks = TrackRecorder(window_s=60.0, spacing_s=0.5)
    >>> for t in range(5):
    ...     tracks.add("robot1", Pose2D(float(t), 0.0, 0.0), stamp_ns=t * 300_000_000)
    >>> [p.x_m for p in tracks.robots()[0].track]
    [0.0, 2.0, 4.0]
    """

    window_s: float = 60.0
    spacing_s: float = 0.25
    _tracks: dict[str, deque[TrackPoint]] = field(default_factory=dict, init=False)
    _latest: dict[str, TrackPoint] = field(default_factory=dict, init=False)

    def __post_init__(self) -> None:
        if not (self.window_s > 0 and self.spacing_s >= 0):
            raise ValueError(f"window_s must be > 0 and spacing_s >= 0, not {self.window_s}, {self.spacing_s}")

    def add(self, namespace: str, pose: Pose2D, *, stamp_ns: int) -> None:
        """Note that robot ``namespace`` was at ``pose`` (map frame) at ``stamp_ns``."""
        point = TrackPoint(pose.x_m, pose.y_m, pose.yaw_rad, stamp_ns)
        robot = namespace.strip("/")
        track = self._tracks.setdefault(robot, deque())
        self._latest[robot] = point
        if not track or stamp_ns - track[-1].stamp_ns >= self.spacing_s * 1e9:
            track.append(point)
        while track and stamp_ns - track[0].stamp_ns > self.window_s * 1e9:
            track.popleft()

    def robots(self) -> list[Robot]:
        """Every robot seen, by name: its newest pose and its track ending there."""
        out = []
        for name in sorted(self._latest):
            latest, track = self._latest[name], list(self._tracks[name])
            if not track or track[-1] != latest:
                track.append(latest)
            out.append(Robot(name, latest, tuple(track)))
        return out
