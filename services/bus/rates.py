"""Message rate and bandwidth over a sliding window, for ``humanoid hz`` and ``humanoid bw``.

Arrival times are wall-clock (``time.monotonic``) in the listening process, like ``ros2 topic hz``:
a topic published every 5 ms of sim time arrives at 200 Hz only when the sim runs at real time.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class RateStats:
    """Statistics of the last ``window`` messages.

    Attributes:
        count: messages received since the start.
        window: messages in the window (the rate uses ``window - 1`` intervals).
        rate_hz: mean rate over the window [Hz] (0 with fewer than 2 messages).
        period_min_s, period_max_s, period_std_s: the intervals between messages [s].
        bytes_per_s: bandwidth over the window [B/s].
        size_mean_b, size_min_b, size_max_b: message sizes in the window [B].
    """

    count: int
    window: int
    rate_hz: float
    period_min_s: float
    period_max_s: float
    period_std_s: float
    bytes_per_s: float
    size_mean_b: float
    size_min_b: int
    size_max_b: int


class RateMeter:
    """Collects ``(arrival time [s], size [B])`` and summarises the last ``window`` of them."""

    def __init__(self, window: int = 1000) -> None:
        if window < 2:
            raise ValueError(f"the window must hold at least 2 messages, not {window}")
        self._times: deque[float] = deque(maxlen=window)
        self._sizes: deque[int] = deque(maxlen=window)
        self.count = 0

    def add(self, t_s: float, size_b: int) -> None:
        self._times.append(t_s)
        self._sizes.append(size_b)
        self.count += 1

    def stats(self) -> RateStats | None:
        """None until two messages arrived."""
        n = len(self._times)
        if n < 2:
            return None
        times = list(self._times)
        periods = [b - a for a, b in itertools.pairwise(times)]
        span = times[-1] - times[0]
        mean = span / len(periods)
        std = math.sqrt(sum((p - mean) ** 2 for p in periods) / len(periods))
        sizes = list(self._sizes)
        # bandwidth: bytes of the messages after the first over the time they took to arrive
        bandwidth = sum(sizes[1:]) / span if span > 0 else 0.0
        return RateStats(
            count=self.count,
            window=n,
            rate_hz=1.0 / mean if mean > 0 else 0.0,
            period_min_s=min(periods),
            period_max_s=max(periods),
            period_std_s=std,
            bytes_per_s=bandwidth,
            size_mean_b=sum(sizes) / n,
            size_min_b=min(sizes),
            size_max_b=max(sizes),
        )


def human_bytes(value: float) -> str:
    """``512 B``, ``12.3 KB``, ``4.56 MB`` (powers of 1000)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("KB", 1e3)):
        if abs(value) >= scale:
            return f"{value / scale:.2f} {unit}"
    return f"{value:.0f} B"
