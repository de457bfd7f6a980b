"""``diag``: a service that answers round trips, to check and measure the bus itself."""

from __future__ import annotations

import os

from services.bus.schemas.diag import ECHO, EchoReply, EchoRequest
from services.bus.service import Service, handles, run_service


class DiagService(Service):
    """Bus diagnostics: echo round trips."""

    name = "diag"

    @handles(ECHO)
    def echo(self, request: EchoRequest) -> EchoReply:
        return EchoReply(text=request.text, blob=request.blob, pid=os.getpid())


if __name__ == "__main__":
    raise SystemExit(run_service(DiagService))
