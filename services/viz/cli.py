"""``humanoid view``: the live Foxglove view of a running stack, in the foreground (until Ctrl-C)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from services.cli_common import examples


def add_cli(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "view",
        help="serve a running stack to Foxglove (WebSocket, ws://127.0.0.1:8765) until Ctrl-C",
        description="Run the viz service in the foreground: the robot (transforms and body), the scene, the "
        "supervisor's map, the plans, the cameras and the log lines of a running stack, served over "
        "Foxglove's WebSocket protocol. In Foxglove: Open connection, Foxglove WebSocket, "
        "ws://127.0.0.1:PORT; load services/viz/layout.json for the panels. `humanoid up --foxglove` "
        "starts the same service with the stack.",
        epilog=examples(
            "humanoid view                                  # beside `humanoid up`: ws://127.0.0.1:8765",
            "humanoid view --port 8766 --duration 600       # another port, for ten minutes",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", type=int, help="WebSocket port (8765; 0: any free port)")
    p.add_argument("--host", help="address to listen on (127.0.0.1)")
    p.add_argument("--model", help="robot model (default: recognised from the joint state)")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    group = p.add_argument_group("bus")
    group.add_argument("--config", help="YAML file with a 'bus:' section (and a 'viz:' section)")
    group.add_argument("--hub", help="zenoh endpoint of the hub (default tcp/127.0.0.1:7447)")
    group.add_argument("--robot", help="robot name in the keys hrp/<robot>/... (default hrp2)")
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    import dataclasses

    from services.bus.config import load_bus_config, load_section
    from services.bus.service import configure_logging, serve
    from services.cli_common import stop_event
    from services.viz.service import VizConfig, VizService

    configure_logging("INFO")
    config = load_section(args.config, "viz", VizConfig)
    changes = {
        k: v for k, v in (("port", args.port), ("host", args.host), ("model", args.model)) if v is not None
    }
    config = dataclasses.replace(config, **changes)
    bus = load_bus_config(args.config, hub=args.hub, robot=args.robot)
    stop = stop_event(args.duration)

    def ready(service: Any) -> None:
        print(
            f"Foxglove: open a connection to ws://{config.host}:{service.port} (Ctrl-C to stop)", flush=True
        )

    serve(VizService, config, bus, stop, ready=ready)
    print("stopped", file=sys.stderr)
    return 0
