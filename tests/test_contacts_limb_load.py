"""The limb-load bound of the contact planner's stability (services/contacts/limb_load.py, an extension
of §2.2 of Escande et al.): the bound holds the arm's joints within their effort limits in any posture,
and a bounded patch shrinks the static-equilibrium region, with the force QP agreeing."""

from __future__ import annotations

import dataclasses
import math

import msgspec
import numpy as np
import pinocchio as pin
import pytest

from services.contacts.environment import environment_of
from services.contacts.limb_load import GRAVITY_M_S2, force_cap_n, limb_joints
from services.contacts.posture import ARM_SPOTS, PostureGenerator, posture_config
from services.contacts.spots import model_with_spots, robot_spots
from services.contacts.stability import (
    ContactPatch,
    equilibrium_forces,
    equilibrium_region,
    is_statically_stable,
)
from services.model import load_robot
from services.model.ground import signed_distance
from sim.scene import layout, load_scene


@pytest.fixture(scope="module")
def arm():
    robot = load_robot("hrp2_like")
    spots = {s.name: s for s in robot_spots(robot)}
    return robot, model_with_spots(robot.model, spots.values()), spots


def test_the_limb_of_a_hand_is_its_arm(arm):
    _robot, model, spots = arm
    hand_joint = model.frames[model.getFrameId(spots["left_hand"].frame_name)].parentJoint
    names = [model.names[j] for j in limb_joints(model, hand_joint)]
    assert names == [f"LARM_JOINT{k}" for k in range(5, -1, -1)]  # up to the shoulder, not the chest


def test_a_capped_force_on_the_hand_keeps_every_arm_joint_within_its_effort(arm):
    """Random arm postures, random force directions at the patch's corners, |f| at the cap: the arm's
    joint torques (own weight + J^T f) stay within the effort limits; 1.5x the cap exceeds one of them
    somewhere (the bound is not vacuous)."""
    _robot, model, spots = arm
    spot = spots["left_hand"]
    cap = force_cap_n(model, spot)
    weight = pin.computeTotalMass(model) * GRAVITY_M_S2
    assert 50.0 < cap < 0.5 * weight  # an arm holds less than half the robot (the fall measured)
    fid = model.getFrameId(spot.frame_name)
    joints = limb_joints(model, model.frames[fid].parentJoint)
    v_idx = [model.joints[j].idx_v for j in joints]
    q_idx = [model.joints[j].idx_q for j in joints]
    effort = np.array(model.effortLimit)[v_idx]
    data = model.createData()
    rng = np.random.default_rng(3)
    worst_at_cap, worst_beyond = 0.0, 0.0
    for _ in range(300):
        q = pin.neutral(model)
        lower, upper = np.array(model.lowerPositionLimit), np.array(model.upperPositionLimit)
        q[q_idx] = rng.uniform(lower[q_idx], upper[q_idx])
        gravity = pin.computeGeneralizedGravity(model, data, q)[v_idx]
        pin.computeJointJacobians(model, data, q)
        pin.framesForwardKinematics(model, data, q)
        for corner in spot.corners_local():
            point = data.oMf[fid].act(corner)
            J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            # the corner's linear Jacobian: v_corner = v_spot + w x (corner - spot)
            J_corner = J[:3] - pin.skew(point - data.oMf[fid].translation).dot(J[3:])
            for direction in rng.normal(size=(8, 3)):
                f = direction / np.linalg.norm(direction)
                tau = gravity + J_corner[:, v_idx].T.dot(f * cap)  # g(q): the torque holding the weight
                worst_at_cap = max(worst_at_cap, float(np.max(np.abs(tau) / effort)))
                tau = gravity + J_corner[:, v_idx].T.dot(f * 1.5 * cap)
                worst_beyond = max(worst_beyond, float(np.max(np.abs(tau) / effort)))
    assert worst_at_cap <= 1.0
    assert worst_beyond > 1.0


def _square(cx: float, cy: float, z: float, half: float = 0.05) -> np.ndarray:
    return np.array([[cx + a * half, cy + b * half, z] for a, b in ((1, 1), (-1, 1), (-1, -1), (1, -1))])


def test_a_load_bound_on_the_hand_shrinks_the_region_and_the_force_qp_agrees():
    """One sole and a hand: unbounded, the CoM may go most of the way to the hand; with the hand's
    |force| bounded to 25 % of the weight, on a hand at the sole's height the region ends where the
    lever rule puts it; on a hand higher up (non-coplanar), the force QP's feasibility agrees with the
    region and its hand force respects the bound."""
    up = np.array([0.0, 0.0, 1.0])
    sole = ContactPatch(_square(0.0, 0.0, 0.0), up, 0.8)
    free = equilibrium_region([sole, ContactPatch(_square(0.6, 0.0, 0.0), up, 0.8)])
    flat = equilibrium_region([sole, ContactPatch(_square(0.6, 0.0, 0.0), up, 0.8, max_load=0.25)])
    assert free[:, 0].max() == pytest.approx(0.65, abs=3e-3)
    # the normal force is bounded by 0.25 / sqrt(1 + mu'^2); the CoM is the vertical forces' barycentre
    mu_in = 0.8 * math.cos(math.pi / 4)
    normal = 0.25 / math.sqrt(1.0 + mu_in**2)
    assert flat[:, 0].max() == pytest.approx((1.0 - normal) * 0.05 + normal * 0.65, abs=3e-3)
    held_hand = ContactPatch(_square(0.6, 0.0, 0.7), up, 0.8, max_load=0.25)
    bounded = equilibrium_region([sole, held_hand])
    assert (
        bounded[:, 0].max()
        < 0.6 * equilibrium_region([sole, ContactPatch(_square(0.6, 0.0, 0.7), up, 0.8)])[:, 0].max()
    )
    rng = np.random.default_rng(2)
    checked = 0
    for x, y in rng.uniform((-0.1, -0.1), (0.5, 0.1), size=(80, 2)):
        com = np.array([x, y, 0.8])
        margin = -float(signed_distance(np.array([x, y]), bounded)[0])  # > 0 inside
        if abs(margin) < 5e-3:
            continue  # on the boundary within the projection's tolerance
        feasible, _ = is_statically_stable([sole, held_hand], com)
        assert feasible == (margin > 0.0), (x, y)
        if feasible:
            forces, _ = equilibrium_forces([sole, held_hand], com)
            assert forces[16:].sum() <= normal + 1e-6  # the hand's 4 corners x 4 cone edges
        checked += 1
    assert checked > 50



def test_the_posture_generator_bounds_the_arms_when_asked():
    robot = load_robot("hrp2_like")
    env = environment_of(layout(load_scene("chair_egress")))
    gen = PostureGenerator(robot, env, robot_spots(robot), posture_config(limb_load=True))
    assert set(gen.max_load) == set(ARM_SPOTS)
    assert all(0.0 < v < 0.5 for v in gen.max_load.values())
    assert PostureGenerator(robot, env, robot_spots(robot), posture_config(limb_load=False)).max_load == {}


def test_the_service_schema_defaults_are_the_planners():
    """contacts/plan and contacts/transition default to the planner's own settings (defaults.py): the
    limb-load bound and f_T's slope a request does not name are those the chair egress stands up with."""
    from services.bus.schemas import contacts as msg
    from services.contacts import defaults
    from services.contacts.planner import PlanProblem

    fields = {f.name: f.default for f in msgspec.structs.fields(msg.PlanRequest)}
    assert fields["limb_load"] is defaults.LIMB_LOAD and fields["slope_k"] == defaults.SLOPE_K
    transition = {f.name: f.default for f in msgspec.structs.fields(msg.TransitionRequest)}
    assert transition["limb_load"] is defaults.LIMB_LOAD
    assert {f.name: f.default for f in dataclasses.fields(PlanProblem)}["slope_k"] == defaults.SLOPE_K
