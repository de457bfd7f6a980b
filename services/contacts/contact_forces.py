"""The planned normal force of each arm contact along a timed transition, for the sim's force-aware
execution (``sim.compliance``: damping control of a limb's contact force, as HRP-2's controller does).

The static equilibrium of §2.2 certifies that forces in the friction cones balance gravity at the CoM;
the force QP (``stability.equilibrium_forces``, the least-norm forces) picks one such distribution.
Along a transition from S1 to S2 the contacts held are S1's (a removed contact is released at q2, a new
one is made at q2: §2.3), so at a sample with CoM c the planned forces are those of S1 at c; for a
removal they are blended, with the transition's progress, into those of S2 at c (the released contact
unloads to zero at q2 instead of jumping there). The hands and forearms get a profile: their arms close
the rigid loops in which position control sets the forces by millimetre errors (``sim/compliance.py``);
the legs carry the rest (force targets on the soles too, or on the arms only when one other contact
closes the loop, fell earlier on the chair egress: services/contacts/README.md, session 9).

Used only when ``InterpolationConfig.force_control`` is on (an experiment, off by default).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from services.contacts.limb_load import GRAVITY_M_S2, limb_joints
from services.contacts.posture import ARM_SPOTS, PostureGenerator
from services.contacts.sets import Contact, ContactSet
from services.contacts.stability import N_GENERATORS, cone_generators, equilibrium_forces
from services.errors import InfeasibleError
from sim.force_target import ForceTarget

CHECK_EVERY_S = 0.1  # the force QP every this much of the motion [s]; linear in between
RESIDUAL_TOL = 1e-6  # a force QP with a larger residual has no equilibrium (its forces are not used)


def normal_forces(gen: PostureGenerator, stable: ContactSet, com: np.ndarray) -> dict[tuple, float] | None:
    """The normal force [N] of each contact of ``stable`` (by (spot, surface)) in the least-norm
    equilibrium at ``com`` (world [m]), or None when there is none (or a patch lies off its surface)."""
    try:
        patches = gen.patches(stable)
    except InfeasibleError:
        return None
    lam, residual = equilibrium_forces(patches, com)
    if residual > RESIDUAL_TOL:
        return None
    weight_n = gen.robot.total_mass_kg * GRAVITY_M_S2
    out, i = {}, 0
    for contact, patch in zip(stable, patches, strict=True):
        n = len(patch.corners_world) * N_GENERATORS
        generators = np.tile(
            cone_generators(patch.normal_world, patch.friction), (len(patch.corners_world), 1)
        )
        force = (lam[i : i + n, None] * generators).sum(axis=0) * weight_n
        out[contact.pair] = float(force.dot(patch.normal_world))
        i += n
    return out


def force_targets(
    gen: PostureGenerator, s1: ContactSet, s2: ContactSet, q: np.ndarray, dt_s: float
) -> tuple[ForceTarget, ...]:
    """The force targets of the arms' contacts of ``s1`` held along the timed transition ``q``
    (N x nq, every ``dt_s`` [s]) from S1 to S2 (module docstring); () when none is chosen or no
    equilibrium is found at the start."""
    arms = [c for c in s1 if c.spot in ARM_SPOTS]
    if not arms:
        return ()
    removal = set(s2) < set(s1)
    n = len(q)
    every = max(1, round(CHECK_EVERY_S / dt_s))
    checks = sorted(set(range(0, n, every)) | {n - 1})
    profile = {c.pair: [] for c in arms}
    last: dict[tuple, float] | None = None
    for i in checks:
        com = pin.centerOfMass(gen.model, gen.data, q[i])
        held = normal_forces(gen, s1, com) or last
        if held is None:
            return ()
        if removal:
            after = normal_forces(gen, s2, com)
            w = i / max(n - 1, 1)
            if after is not None:
                held = {pair: (1.0 - w) * f + w * after.get(pair, 0.0) for pair, f in held.items()}
        last = held
        for c in arms:
            profile[c.pair].append(held[c.pair])
    return tuple(_target(gen, c, np.interp(np.arange(n), checks, profile[c.pair])) for c in arms)


def _target(gen: PostureGenerator, contact: Contact, force_n: np.ndarray) -> ForceTarget:
    """The sim's force target of an arm contact with its force profile."""
    frame = gen.model.frames[gen.model.getFrameId(gen.spots[contact.spot].frame_name)]
    joints = tuple(gen.model.names[j] for j in limb_joints(gen.model, frame.parentJoint))
    surface = gen.env.surface(contact.surface)
    normal = tuple(float(v) for v in surface.T_world_surface.rotation[:, 2])
    point = tuple(float(v) for v in frame.placement.translation)  # the spot in its joint's frame
    return ForceTarget(joints, surface.owner, normal, force_n, point)
