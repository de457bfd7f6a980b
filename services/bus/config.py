"""Bus configuration: one frozen dataclass, defaults in code, optional YAML override.

Defaults keep everything on this machine: peer mode, loopback TCP only, multicast scouting off.
Every session listens on a free loopback port and connects to the *hub* endpoint, on which the
launcher (``humanoid up``) listens; gossip over that first link lets the peers find each other, and
they stay connected directly if the hub goes away. Another host is a configuration change:
see the README ("Running on several hosts").
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import yaml

from services.errors import InvalidRequestError

DEFAULT_HUB = "tcp/127.0.0.1:7447"


@dataclass(frozen=True)
class BusConfig:
    """How a process joins the bus.

    Attributes:
        robot: the ``<robot>`` segment of every key (``hrp/<robot>/...``).
        mode: zenoh mode, ``peer`` or ``client`` (``router`` needs zenohd).
        hub: the endpoint the launcher listens on and every other session connects to.
        listen: endpoints this session listens on (``tcp/127.0.0.1:0`` = a free loopback port).
        connect: extra endpoints to connect to (other hosts, a zenoh router).
        multicast_scouting: UDP multicast discovery; off so nothing leaves the machine by default.
        shared_memory: zenoh's shared-memory transport between local processes. Off by default: a
            pool segment unlinked while in use made large messages vanish with no error (the
            supervisor's 2 MB sim/execute requests in the full test suite, see ``shm.py``), and
            loopback TCP is fast enough (``scripts/bench bus``: 640x480 stereo pairs at 520 pairs/s,
            960 MB/s, without it).
        zenoh: raw zenoh config overrides, ``{"path/in/config": value}``, applied last. In string
            values ``{identity}`` stands for this process's :attr:`identity` (one YAML file gives every
            service its own TLS certificate: ``certs/{identity}.pem``; see the README, "Access control").
        identity: who this process is on the bus (the common name of its certificate in a TLS
            deployment); empty: the service's name, ``hub`` for the launcher, ``client`` otherwise.
    """

    robot: str = "hrp2"
    mode: str = "peer"
    hub: str = DEFAULT_HUB
    listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    shared_memory: bool = False
    zenoh: dict[str, Any] = field(default_factory=dict)
    identity: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.robot, str):
            raise InvalidRequestError(f"robot name must be a string, got {self.robot!r}")
        if self.identity and not self.identity.replace("_", "").replace("-", "").isalnum():
            raise InvalidRequestError(f"identity {self.identity!r} must be letters, digits, _ and -")
        if self.mode not in ("peer", "client"):
            raise InvalidRequestError(f"bus mode {self.mode!r} is not one of: peer, client")
        if not self.robot.replace("_", "").isalnum() or not self.robot[:1].isalpha():
            raise InvalidRequestError(f"robot name {self.robot!r} must be lower_snake_case")

    def with_hub_port(self, port: int) -> BusConfig:
        """The same config with the hub on loopback port ``port`` (tests run hubs side by side)."""
        return dataclasses.replace(self, hub=f"tcp/127.0.0.1:{port}")

    def zenoh_config(self, *, as_hub: bool = False, identity: str = "") -> Any:
        """Build the ``zenoh.Config`` (``as_hub``: listen on the hub endpoint instead of connecting;
        ``identity``: the process's name when :attr:`identity` is not set, e.g. the service's)."""
        import zenoh

        who = self.identity or identity or ("hub" if as_hub else "client")

        listen = [self.hub] if as_hub else list(self.listen)
        connect = list(self.connect) + ([] if as_hub else [self.hub])
        conf = zenoh.Config()
        entries: dict[str, Any] = {
            "mode": self.mode,
            "listen/endpoints": listen,
            "connect/endpoints": connect,
            "scouting/multicast/enabled": self.multicast_scouting,
            # Keep retrying the hub, quickly: a service may start before it (or outlive a restart of it).
            # -1 = retry forever in the background (0 would give up after the first attempt).
            "connect/retry": {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2},
            "connect/timeout_ms": -1,
            "connect/exit_on_failure": False,
            "transport/shared_memory/enabled": self.shared_memory,
        }
        entries.update({path: _with_identity(value, who) for path, value in self.zenoh.items()})
        for path, value in entries.items():
            try:
                conf.insert_json5(path, json.dumps(value))
            except Exception as exc:  # zenoh raises ZError with its own message
                raise InvalidRequestError(f"bad zenoh config entry {path}={value!r}: {exc}") from None
        return conf


def _with_identity(value: Any, identity: str) -> Any:
    """``value`` with ``{identity}`` replaced in every string inside it."""
    if isinstance(value, str):
        return value.replace("{identity}", identity)
    if isinstance(value, list | tuple):
        return [_with_identity(v, identity) for v in value]
    if isinstance(value, dict):
        return {k: _with_identity(v, identity) for k, v in value.items()}
    return value


def load_bus_config(path: str | Path | None = None, **overrides: Any) -> BusConfig:
    """Defaults, then the ``bus:`` section of a YAML file, then ``overrides``."""
    values: dict[str, Any] = {}
    if path is not None:
        values.update(_yaml_section(path, "bus"))
    values.update({k: v for k, v in overrides.items() if v is not None})
    return from_mapping(BusConfig, values, where=str(path or "defaults"))


def _yaml_section(path: str | Path, section: str) -> dict[str, Any]:
    try:
        doc = yaml.safe_load(Path(path).read_text()) or {}
    except FileNotFoundError:
        raise InvalidRequestError(f"config file {path} does not exist") from None
    except (yaml.YAMLError, UnicodeDecodeError, RecursionError) as exc:
        raise InvalidRequestError(f"config file {path} is not valid YAML: {exc}") from None
    if not isinstance(doc, dict):
        raise InvalidRequestError(f"config file {path} must be a mapping at the top level")
    sub = doc.get(section) or {}
    if not isinstance(sub, dict):
        raise InvalidRequestError(f"section {section!r} of {path} must be a mapping")
    return sub


def load_section(path: str | Path | None, section: str, config_type: type) -> Any:
    """Defaults of ``config_type`` overridden by the ``<section>:`` mapping of a YAML file."""
    values = _yaml_section(path, section) if path is not None else {}
    return from_mapping(config_type, values, where=f"{path}:{section}" if path else "defaults")


def from_mapping(config_type: type, values: dict[str, Any], *, where: str) -> Any:
    """Build a frozen config dataclass from YAML values through ``msgspec.convert`` (strict types).

    Unknown keys are refused with the list of valid ones; a wrong type names the field path and
    what was expected (``foxglove_views: "no"`` -> "Expected `bool`, got `str` - at `$.foxglove_views`";
    ``listen: "tcp/..."`` -> "Expected `array`, got `str`"); the dataclass's ``__post_init__`` checks
    the ranges.
    """
    if not isinstance(values, dict):
        raise InvalidRequestError(f"{config_type.__name__} in {where} must be a mapping")
    fields = {f.name: f for f in dataclasses.fields(config_type)}
    unknown = sorted(str(k) for k in set(values) - set(fields))
    if unknown:
        raise InvalidRequestError(
            f"unknown {config_type.__name__} option(s) {', '.join(unknown)} in {where}; "
            f"valid options: {', '.join(fields)}"
        )
    try:
        return msgspec.convert(values, config_type, strict=True)
    except msgspec.ValidationError as exc:
        raise InvalidRequestError(f"bad {config_type.__name__} in {where}: {exc}") from None
    except RecursionError:
        raise InvalidRequestError(f"bad {config_type.__name__} in {where}: nested too deeply") from None
