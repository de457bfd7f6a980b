"""Message schemas of the stack: one module per service, all discovered here.

Every module in this package declares msgspec Structs (units in the field docs) and the
:class:`~services.bus.spec.EndpointSpec` / :class:`~services.bus.spec.TopicSpec` objects of one
service. :func:`endpoints` and :func:`topics` collect them for the CLI, the recorder and replay.
"""

from __future__ import annotations

import importlib
import pkgutil
from functools import cache

from services.bus.spec import EndpointSpec, TopicSpec


@cache
def _specs() -> tuple[dict[str, EndpointSpec], dict[str, TopicSpec]]:
    endpoints: dict[str, EndpointSpec] = {}
    topics: dict[str, TopicSpec] = {}
    for info in pkgutil.iter_modules(__path__):
        module = importlib.import_module(f"{__name__}.{info.name}")
        for value in vars(module).values():
            if isinstance(value, EndpointSpec):
                endpoints[value.path] = value
            elif isinstance(value, TopicSpec):
                topics[value.path] = value
    return endpoints, topics


def endpoints() -> dict[str, EndpointSpec]:
    """All endpoint specs by ``service/name``."""
    return _specs()[0]


def topics() -> dict[str, TopicSpec]:
    """All topic specs by ``service/name``."""
    return _specs()[1]
