"""The scene as it is (``/world/objects``) for a viewer and for a log: both ask ``sim/ground_truth``
with :func:`ask`.

The sim mirrors its reply on ``hrp/<robot>/sim/ground_truth/reply`` to whoever subscribes; the
converters (:mod:`services.viz.converter`) turn that copy into ``/world/objects``, whether it reaches
the live view (:mod:`services.viz.service`, while a viewer watches the topic) or the recorder
(:mod:`services.bus.recorder`, which writes the copy and its view into the log). One request, one
conversion, the same in both.

Ground truth is a viewer's privilege: the supervisor and the planners never read it (they know the
world through perception).
"""

from __future__ import annotations

import contextlib

import zenoh

from services.bus import keys
from services.bus.schemas import sim as sim_msg
from services.bus.spec import EndpointSpec

#: The sim's endpoints after whose answer the world may have changed: a motion, the gripper, a reset.
MOVING = (sim_msg.EXECUTE, sim_msg.GRIPPER, sim_msg.RESET)


def mirror_key(robot: str) -> str:
    """The key of the copy of ``sim/ground_truth``'s reply, which the converters read."""
    return keys.reply_mirror(robot, sim_msg.GROUND_TRUTH.service, sim_msg.GROUND_TRUTH.name)


def ask(session: zenoh.Session, robot: str, spec: EndpointSpec, timeout_s: float) -> bool:
    """One request to ``spec`` (:data:`~services.bus.schemas.sim.GROUND_TRUTH`, named by the caller:
    ``humanoid graph`` reads a service's calls from the specs its source names), whose reply reaches
    the subscribers of :func:`mirror_key`; whether the sim answered within ``timeout_s`` [s] (no sim:
    False at once)."""
    if spec is not sim_msg.GROUND_TRUTH:
        raise ValueError(f"the world is asked of sim/ground_truth, not {spec.path}")
    answered = False
    with contextlib.suppress(zenoh.ZError):  # the session closing under a stopping service
        for reply in session.get(keys.key(robot, spec.service, spec.name), payload=b"{}", timeout=timeout_s):
            answered = answered or reply.ok is not None
    return answered


def moving_keys(robot: str) -> frozenset[str]:
    """The keys of the reply and error copies of :data:`MOVING`: after one, the world is asked again."""
    return frozenset(
        mirror(robot, spec.service, spec.name)
        for spec in MOVING
        for mirror in (keys.reply_mirror, keys.error_mirror)
    )
