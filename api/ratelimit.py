"""Per-caller rate limits: one token bucket in memory per API key (or client address)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

from api.errors import ApiConfigError


class TokenBucketLimiter:
    """Token buckets by name: each refills at ``rate_per_s`` up to ``burst`` tokens; a request takes one.

    Thread-safe (sync routes run in a thread pool). State lives in this process only, so each
    API process limits on its own. Buckets that have refilled completely are forgotten once
    more than ``max_buckets`` exist, which bounds memory whatever the callers send.

    Parameters
    ----------
    rate_per_s : float
        Sustained requests per second allowed per bucket (> 0).
    burst : int
        Requests allowed at once after a quiet spell (>= 1).
    clock : callable, optional
        Monotonic seconds; tests pass a fake one.
    max_buckets : int
        How many buckets to keep before forgetting full ones.

    Examples
    --------
    >>> now = [0.0]
    >>> limiter = TokenBucketLimiter(rate_per_s=2.0, burst=2, clock=lambda: now[0])
    >>> [limiter.take("k") for _ in range(3)]
    [0.0, 0.0, 0.5]
    >>> now[0] = 0.5
    >>> limiter.take("k")
    0.0
    """

    def __init__(self, *, rate_per_s: float, burst: int, clock: Callable[[], float] = time.monotonic,
                 max_buckets: int = 10_000) -> None:
        if not (math.isfinite(rate_per_s) and rate_per_s > 0):
            raise ApiConfigError(f"rate limit must be a positive number of requests per second, not {rate_per_s}")
        if burst < 1:
            raise ApiConfigError(f"rate limit burst must be at least 1 request, not {burst}")
        if max_buckets < 1:
            raise ApiConfigError(f"max_buckets must be at least 1, not {max_buckets}")
        self.rate_per_s = rate_per_s
        self.burst = burst
        self._clock = clock
        self._max_buckets = max_buckets
        self._buckets: dict[str, tuple[float, float]] = {}  # name -> (tokens, at)
        self._lock = threading.Lock()

    def take(self, bucket: str) -> float:
        """Take a token from ``bucket``: 0.0 if the request may go, else seconds until a token is due."""
        with self._lock:
            now = self._clock()
            tokens, at = self._buckets.get(bucket, (float(self.burst), now))
            tokens = min(float(self.burst), tokens + (now - at) * self.rate_per_s)
            if tokens >= 1.0:
                self._buckets[bucket] = (tokens - 1.0, now)
                if len(self._buckets) > self._max_buckets:
                    self._forget_full(now)
                return 0.0
            self._buckets[bucket] = (tokens, now)
            return (1.0 - tokens) / self.rate_per_s

    def _forget_full(self, now: float) -> None:
        self._buckets = {name: (tokens, at) for name, (tokens, at) in self._buckets.items()
                         if tokens + (now - at) * self.rate_per_s < self.burst}
