"""Which revisions a retention policy keeps: pure, on (id, stage, time, pinned) records.

Every revision of the last ``keep_all_s`` stays; older ones are thinned to the newest of each hour for
``hourly_s`` more, then to the newest of each day (UTC). Revisions of a protected stage (an operator's or the
WMS's), pinned ones, the map's newest and each stage's newest are never thinned.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from shared.store.records import StoreError

_HOUR_S = 3600.0
_DAY_S = 86400.0


@dataclass(frozen=True, slots=True)
class RetentionPolicy:
    """How long every revision stays, and how older ones are thinned.

    Parameters
    ----------
    keep_all_s : float
        Revisions younger than this (seconds) are all kept.
    hourly_s : float
        For this many seconds beyond ``keep_all_s``, the newest revision of each hour is kept; older than that,
        the newest of each day (UTC).
    keep_stages : frozenset of str
        Stages whose revisions are never thinned (people's and the WMS's writes).
    """

    keep_all_s: float
    hourly_s: float
    keep_stages: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        for name, value in (("keep_all_s", self.keep_all_s), ("hourly_s", self.hourly_s)):
            if not (math.isfinite(value) and value >= 0):
                raise StoreError(f"retention {name} must be a finite number of seconds >= 0, not {value}")


@dataclass(frozen=True, slots=True)
class RevisionAge:
    """What retention needs to know of a revision."""

    id: int
    stage: str
    created_at: dt.datetime
    pinned: bool = False


def revisions_to_keep(revisions: Sequence[RevisionAge], policy: RetentionPolicy, *, now: dt.datetime
                      ) -> set[int]:
    """Ids of the ``revisions`` (of one map) that ``policy`` keeps at time ``now``; the rest may be thinned.

    >>> t = dt.datetime(2026, 1, 2, tzinfo=dt.UTC)
    >>> old = [RevisionAge(i, "occupancy", t - dt.timedelta(hours=3, minutes=i)) for i in range(1, 4)]
    >>> sorted(revisions_to_keep(old, RetentionPolicy(3600, 86400), now=t))  # the newest: id 1
    [1]
    """
    if not revisions:
        return set()
    keep = {max(r.id for r in revisions)}
    newest_of: dict[tuple[str, float], int] = {}
    for revision in revisions:
        age_s = (now - revision.created_at).total_seconds()
        if age_s <= policy.keep_all_s or revision.pinned or revision.stage in policy.keep_stages:
            keep.add(revision.id)
            continue
        period = _HOUR_S if age_s <= policy.keep_all_s + policy.hourly_s else _DAY_S
        bucket = (f"{period:.0f}", revision.created_at.timestamp() // period)
        newest_of[bucket] = max(newest_of.get(bucket, 0), revision.id)
    keep.update(newest_of.values())
    keep.update(_newest_per_stage(revisions))
    return keep


def _newest_per_stage(revisions: Iterable[RevisionAge]) -> set[int]:
    newest: dict[str, int] = {}
    for revision in revisions:
        newest[revision.stage] = max(newest.get(revision.stage, 0), revision.id)
    return set(newest.values())
