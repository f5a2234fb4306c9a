"""api.ratelimit: token buckets refill at the rate up to the burst, separately per name, in bounded memory."""

from __future__ import annotations

import numpy as np
import pytest

from api.errors import ApiConfigError
from api.ratelimit import TokenBucketLimiter


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def test_burst_goes_at_once_then_one_request_per_refill() -> None:
    clock = FakeClock()
    limiter = TokenBucketLimiter(rate_per_s=4.0, burst=3, clock=clock)

    assert [limiter.take("k") for _ in range(3)] == [0.0, 0.0, 0.0]
    assert limiter.take("k") == pytest.approx(0.25)
    clock.now_s = 0.25
    assert limiter.take("k") == 0.0
    assert limiter.take("k") > 0.0


def test_buckets_are_separate_per_name() -> None:
    limiter = TokenBucketLimiter(rate_per_s=1.0, burst=1, clock=FakeClock())

    assert limiter.take("a") == 0.0
    assert limiter.take("a") > 0.0
    assert limiter.take("b") == 0.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_never_more_than_burst_plus_rate_times_elapsed(seed: int) -> None:
    rng = np.random.default_rng(seed)
    clock = FakeClock()
    rate_per_s, burst = rng.uniform(0.5, 20.0), int(rng.integers(1, 10))
    limiter = TokenBucketLimiter(rate_per_s=rate_per_s, burst=burst, clock=clock)
    allowed = 0
    for step in rng.exponential(0.05, 2000):
        clock.now_s += step
        allowed += limiter.take("k") == 0.0

    assert allowed <= burst + rate_per_s * clock.now_s
    assert allowed >= rate_per_s * clock.now_s * 0.5  # a steady stream is not starved


def test_memory_stays_bounded_whatever_names_callers_send() -> None:
    clock = FakeClock()
    limiter = TokenBucketLimiter(rate_per_s=10.0, burst=5, clock=clock, max_buckets=100)

    for i in range(10_000):
        clock.now_s += 0.01
        limiter.take(f"address:{i}")

    assert len(limiter._buckets) <= 101


@pytest.mark.parametrize(("options", "message"), [
    ({"rate_per_s": 0.0, "burst": 1}, "positive number"),
    ({"rate_per_s": float("nan"), "burst": 1}, "positive number"),
    ({"rate_per_s": 1.0, "burst": 0}, "at least 1 request"),
    ({"rate_per_s": 1.0, "burst": 1, "max_buckets": 0}, "max_buckets"),
])
def test_nonsense_limits_are_refused(options: dict[str, float], message: str) -> None:
    with pytest.raises(ApiConfigError, match=message):
        TokenBucketLimiter(**options)  # type: ignore[arg-type]
