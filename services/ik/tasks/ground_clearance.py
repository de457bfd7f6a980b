"""Points of the robot kept above the ground plane: the inequality form of eqs. (12)-(13) of the
footstep paper with the ground as the other body.

For a point P fixed in a link frame (e.g. a corner of a hand's collision box) and the horizontal
ground z = ``ground_z_m``,

    G = ground_z + clearance - z_P <= 0,      dG = -e_z^T J_P dq,

with J_P the point's translation Jacobian (P held fixed in its link). With the task's gain lambda
the solver bounds dG by -lambda G (eq. 4): the point may approach the ground at most lambda times its
distance to the clearance per unit of IK time, the velocity damper of eqs. (11) and (13). The lowest
point of a convex polytope above a plane is one of its vertices, so a box's eight corners keep the
whole box above the ground.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import LWA, frame_id
from services.ik.task import Task


class GroundClearanceTask(Task):
    """Keep every point of ``points`` (frame name, (x, y, z) in that frame [m]) at least
    ``clearance_m`` above the ground plane z = ``ground_z_m`` (model frame, z up) [m].

    One row per point closer than ``clearance_m + activation_m`` to the ground (a point far above
    it constrains nothing); a frame's placement and Jacobian are read once per evaluation.
    """

    def __init__(
        self,
        model: pin.Model,
        points: Sequence[tuple[str, Sequence[float]]],
        clearance_m: float = 0.01,
        ground_z_m: float = 0.0,
        activation_m: float = 0.05,
        gain: float = 1.0,
        name: str = "ground_clearance",
    ) -> None:
        super().__init__(name, gain, lower=-np.inf, upper=0.0)
        if not points:
            raise InvalidRequestError(f"task {name!r}: needs at least one point")
        if not (np.isfinite(clearance_m) and np.isfinite(ground_z_m) and activation_m >= 0.0):
            raise InvalidRequestError(
                f"task {name!r}: clearance_m and ground_z_m must be finite and activation_m >= 0, got "
                f"{clearance_m}, {ground_z_m}, {activation_m}"
            )
        self.model = model
        fids = [frame_id(model, frame) for frame, _ in points]
        self._frames, self._frame_of = np.unique(np.array(fids), return_inverse=True)
        self._frames = [int(f) for f in self._frames]
        self.local = np.array([p for _, p in points], dtype=float).reshape(-1, 3)
        self.ground_z_m = float(ground_z_m)
        self.clearance_m = float(clearance_m)
        self.level_m = self.ground_z_m + self.clearance_m  # the lowest allowed height of a point
        self.activation_m = float(activation_m)

    def heights(self, data: pin.Data) -> np.ndarray:
        """Height [m] of every point above the ground plane (``data`` holds the frame placements)."""
        return self._world(data)[1][:, 2] - self.ground_z_m

    def _world(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """(offsets R p (k, 3), world points (k, 3)) [m] of every point."""
        H = np.array([data.oMf[f].homogeneous for f in self._frames])[self._frame_of]
        offsets = np.einsum("kij,kj->ki", H[:, :3, :3], self.local)
        return offsets, offsets + H[:, :3, 3]

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        offsets, world = self._world(data)
        G = self.level_m - world[:, 2]
        active = np.flatnonzero(-self.activation_m < G)
        if not active.shape[0]:
            return np.zeros(0), np.zeros((0, self.model.nv))
        J_of: dict[int, np.ndarray] = {}
        rows = np.empty((active.shape[0], self.model.nv))
        for r, k in enumerate(active.tolist()):
            f = int(self._frame_of[k])
            J = J_of.get(f)
            if J is None:
                J = J_of[f] = pin.getFrameJacobian(self.model, data, self._frames[f], LWA)
            # z of v_P = v + w x r: v_z + w_x r_y - w_y r_x
            rx, ry = offsets[k, 0], offsets[k, 1]
            rows[r] = -(J[2] + ry * J[3] - rx * J[4])
        return G[active], rows
