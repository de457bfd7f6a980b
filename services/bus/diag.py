"""``diag``: a service to check and measure the bus itself.

* ``diag/echo``: returns the request (in zenoh's callback); ``diag/echo_worker``: the same on a
  worker thread, like a planner's endpoint;
* ``diag/raise``: answers with the error code asked for (``bug``: an unexpected exception);
* ``diag/ping`` -> ``diag/pong``: republishes every ping (pub/sub round trips);
* ``diag/stream``: publishes stereo pairs on ``diag/frames`` as fast as the bus takes them, for at
  most ``time_budget_s`` (then a ``timeout`` error says how many were sent).

Left out of :func:`services.bus.discovery.default_services` (``humanoid up`` is to start it only when
named in ``--services``): ``diag/raise`` and ``diag/stream`` are tools for tests and benchmarks, not
for a deployed robot.
"""

from __future__ import annotations

import time

import numpy as np
import zenoh

from services.bus.schemas.diag import (
    ECHO,
    ECHO_WORKER,
    FRAMES,
    PING,
    PONG,
    RAISE,
    STREAM,
    EchoReply,
    EchoRequest,
    Ping,
    RaiseReply,
    RaiseRequest,
    StereoFrame,
    StreamReply,
    StreamRequest,
)
from services.bus.service import Service, handles, run_service, subscribes
from services.errors import ERROR_CODES, InvalidRequestError, RequestTimeoutError, error_from_code

MAX_STREAM_PIXELS = 4096 * 4096


class DiagService(Service):
    """Bus diagnostics: echo, error replies, ping/pong, stereo streaming."""

    name = "diag"

    def start(self) -> None:
        self._pong = self.publisher(PONG)
        # Streams measure throughput: wait for the network rather than dropping frames.
        self._frames = self.publisher(FRAMES, congestion_control=zenoh.CongestionControl.BLOCK)

    @handles(ECHO, blocking=False)
    def echo(self, request: EchoRequest) -> EchoReply:
        return EchoReply(text=request.text, blob=request.blob)

    @handles(ECHO_WORKER)
    def echo_worker(self, request: EchoRequest) -> EchoReply:
        return EchoReply(text=request.text, blob=request.blob)

    @handles(RAISE)
    def raise_error(self, request: RaiseRequest) -> RaiseReply:
        if request.code == "bug":
            raise RuntimeError(request.message)
        if request.code not in ERROR_CODES:
            raise InvalidRequestError(
                f"code {request.code!r} is not one of: {', '.join((*ERROR_CODES, 'bug'))}",
                {"field": "code"},
            )
        raise error_from_code(request.code, request.message)

    @subscribes(PING, blocking=False)
    def on_ping(self, ping: Ping) -> None:
        self._pong.put(ping)

    @handles(STREAM)
    def stream(self, request: StreamRequest) -> StreamReply:
        if not (1 <= request.count <= 100_000):
            raise InvalidRequestError(f"count={request.count} must be within 1..100000", {"field": "count"})
        if not (1 <= request.width * request.height <= MAX_STREAM_PIXELS and request.width > 0):
            raise InvalidRequestError(
                f"{request.width}x{request.height} px must be positive and at most {MAX_STREAM_PIXELS} px",
                {"field": "width"},
            )
        rng = np.random.default_rng(0)
        left = rng.integers(0, 256, (request.height, request.width, 3), dtype=np.uint8)
        right = np.roll(left, 8, axis=1)
        started = time.perf_counter()
        for seq in range(request.count):
            elapsed = time.perf_counter() - started
            if elapsed > request.time_budget_s:
                raise RequestTimeoutError(
                    f"diag/stream stopped at its time budget of {request.time_budget_s} s after {seq} of "
                    f"{request.count} pairs",
                    {"sent": seq, "elapsed_s": elapsed},
                )
            self._frames.put(StereoFrame(seq=seq, stamp_s=time.time(), left=left, right=right))
        return StreamReply(sent=request.count, elapsed_s=time.perf_counter() - started)


if __name__ == "__main__":
    raise SystemExit(run_service(DiagService))
