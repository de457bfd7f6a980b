"""Static stability with non-coplanar contacts (§2.2 of Escande et al.: "stability" among the posture
generator's constraints).

A set of flat contacts holds the robot statically when there are contact forces inside the friction
cones that balance gravity at the centre of mass. Each contact is a convex patch; its force
distribution is represented by a force at each corner of the patch, inside the cone linearized by
``N_GENERATORS`` edges (f = sum_k lambda_k u_k, lambda_k >= 0). The Newton-Euler equations with gravity
only (m g pointing down along -z):

    sum_j f_j = (0, 0, m g)
    sum_j p_j x f_j + c x (0, 0, -m g) = 0

are linear in (lambda, c_x, c_y) and independent of c_z: the CoM positions that admit forces form a
convex polygon of the horizontal plane, the static-equilibrium region, which we compute as the
projection of that polytope onto (c_x, c_y) by Bretl and Lall's incremental algorithm (Bretl & Lall,
"Testing static equilibrium for legged robots", IEEE T-RO 2008): linear programs in directions normal
to the current inner approximation's edges until inner and outer approximations agree. The posture
generator then keeps the CoM inside that polygon (a fixed polygon: the contacts taking part in the
stability are fixed while a posture is generated, §2.3). A direct check of a given CoM is the force
feasibility QP solved with proxsuite (:func:`is_statically_stable`).

Extension (not in the paper, which checks friction only): a patch may bound the force it carries,
``ContactPatch.max_load`` (|f| as a fraction of the robot's weight; what the limb's joints can hold,
``limb_load.py``). A force in the linearized cone, f = sum_k lambda_k u_k, has |f| <= sqrt(1 + mu'^2)
sum_k lambda_k (each edge u_k has length sqrt(1 + mu'^2) per unit normal force), so the bound enters as
one linear inequality per patch, sum of its lambdas <= max_load / sqrt(1 + mu'^2): the LPs of the
projection and the force QP keep it, and the region shrinks to the CoM positions the limbs can hold.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType

import numpy as np
import proxsuite
import scipy
import scipy.sparse
from scipy.optimize import linprog

from services.errors import InfeasibleError
from services.model.ground import convex_hull_indices

WARM_LP_SCIPY = ((1, 17),)
"""The scipy releases (major, minor) whose bundled HiGHS bindings :class:`_WarmLP` was checked against
(``scipy.optimize._highspy._core``: private, its layout may change in any release; scipy 1.17 bundles
HiGHS 1.12). Another scipy runs the same LPs through the public ``linprog``, cold (8x slower, the same
regions up to the LPs' tolerance: tests/test_contacts.py); after checking a new release, add it here."""


def _scipy_highs(version: str = scipy.__version__) -> ModuleType | None:
    """scipy's bundled HiGHS bindings when scipy ``version`` is one of :data:`WARM_LP_SCIPY`, else None."""
    try:
        release = tuple(int(part) for part in version.split(".")[:2])
    except ValueError:
        return None
    if release not in WARM_LP_SCIPY:
        return None
    try:
        from scipy.optimize._highspy import _core
    except ImportError:
        return None
    return _core


_highs = _scipy_highs()  # HiGHS driven directly: one model per region, re-solved warm (_WarmLP)

N_GENERATORS = 4  # edges of each linearized friction cone
REGION_BOUND_M = 5.0  # the region is clipped to this square around the contacts [m] (unbounded LPs)


@dataclass(frozen=True)
class ContactPatch:
    """A contact taking part in the stability: its patch corners in the world (k x 3) [m], its unit
    normal pointing out of the environment into the robot (world), and the friction coefficient."""

    corners_world: np.ndarray
    normal_world: np.ndarray
    friction: float
    max_load: float = math.inf  # largest |force| on the whole patch, as a fraction of the weight m g


def _inscribed_mu(mu: float, n: int = N_GENERATORS) -> float:
    """mu' of the polyhedral cone inscribed in the circular one (its section's inscribed polygon)."""
    return mu * math.cos(math.pi / n)


def cone_generators(normal: np.ndarray, mu: float, n: int = N_GENERATORS) -> np.ndarray:
    """(n, 3) unit-free edges n + mu (cos a t1 + sin a t2) of the inner linearized friction cone: the
    polyhedral cone inscribed in the circular one, so that a force in it is always admissible."""
    normal = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    mu_in = _inscribed_mu(mu, n)
    angles = 2.0 * math.pi * np.arange(n) / n
    return normal + mu_in * (np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2)


def _equilibrium_system(patches: Sequence[ContactPatch]) -> tuple[np.ndarray, np.ndarray]:
    """(A, b) with A [lambda; c_x; c_y] = b: the Newton-Euler equations per unit weight (m g = 1)."""
    columns = []
    for patch in patches:
        generators = cone_generators(patch.normal_world, patch.friction)
        for p in np.asarray(patch.corners_world, dtype=float):
            for u in generators:
                columns.append(np.concatenate((u, np.cross(p, u))))
    if not columns:
        raise InfeasibleError("no contact takes part in the stability: nothing can hold the robot")
    A_force = np.array(columns).T  # (6, n_lambda)
    # gravity's moment c x (0, 0, -1) = (-c_y, c_x, 0)
    A_com = np.zeros((6, 2))
    A_com[3, 1] = -1.0
    A_com[4, 0] = 1.0
    b = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    return np.hstack((A_force, A_com)), b


def _load_rows(patches: Sequence[ContactPatch]) -> tuple[np.ndarray, np.ndarray]:
    """(A_ub, b_ub) over the lambdas (columns in ``_equilibrium_system``'s order): one row per patch
    with a finite ``max_load``, sum of the patch's lambdas <= max_load / sqrt(1 + mu'^2)."""
    sizes = [len(p.corners_world) * N_GENERATORS for p in patches]
    rows, bounds = [], []
    start = 0
    for patch, size in zip(patches, sizes, strict=True):
        if math.isfinite(patch.max_load):
            row = np.zeros(sum(sizes))
            row[start : start + size] = 1.0
            rows.append(row)
            mu_in = _inscribed_mu(patch.friction)
            bounds.append(max(patch.max_load, 0.0) / math.sqrt(1.0 + mu_in * mu_in))
        start += size
    return np.array(rows).reshape(-1, sum(sizes)), np.array(bounds)


class _WarmLP:
    """The projection's LPs over one polytope (A_eq x = b_eq, A_ub x <= b_ub, bounds), only the cost
    changing from one to the next: one HiGHS model, each solve warm-started by the simplex from the
    last basis (about 0.05 ms an LP against 1.5 ms through ``linprog``, which builds and checks the
    model anew each time: the regions were an eighth of the search's time)."""

    def __init__(self, A_eq, b_eq, A_ub, b_ub, bounds) -> None:
        inf = _highs.kHighsInf
        rows = A_eq if A_ub is None else np.vstack((A_eq, A_ub))
        n_ub = 0 if A_ub is None else A_ub.shape[0]
        self.n = A_eq.shape[1]
        lp = _highs.HighsLp()
        lp.num_col_, lp.num_row_ = self.n, rows.shape[0]
        lp.col_cost_ = np.zeros(self.n)
        lp.col_lower_ = np.array([-inf if lo is None else lo for lo, _ in bounds], dtype=float)
        lp.col_upper_ = np.array([inf if hi is None else hi for _, hi in bounds], dtype=float)
        lp.row_lower_ = np.concatenate((b_eq, np.full(n_ub, -inf)))
        lp.row_upper_ = np.concatenate((b_eq, np.zeros(0) if b_ub is None else b_ub))
        matrix = scipy.sparse.csc_matrix(rows)
        lp.a_matrix_.format_ = _highs.MatrixFormat.kColwise
        lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = self.n, rows.shape[0]
        lp.a_matrix_.start_, lp.a_matrix_.index_, lp.a_matrix_.value_ = (
            matrix.indptr,
            matrix.indices,
            matrix.data,
        )
        self.highs = _highs._Highs()
        self.highs.setOptionValue("output_flag", False)
        self.highs.passModel(lp)
        self.columns = np.arange(self.n, dtype=np.int32)

    def __call__(self, cost: np.ndarray) -> np.ndarray | None:
        """The optimum's last two coordinates (the CoM's x, y) for ``cost``, None if not optimal."""
        self.highs.changeColsCost(self.n, self.columns, cost)
        self.highs.run()
        if self.highs.getModelStatus() != _highs.HighsModelStatus.kOptimal:
            return None
        return np.array(self.highs.getSolution().col_value[-2:])


def equilibrium_region(
    patches: Sequence[ContactPatch], tol_m: float = 2e-3, max_lps: int = 60, warm: bool = True
) -> np.ndarray:
    """The static-equilibrium CoM region (k x 2 counter-clockwise polygon [m]) by Bretl and Lall's
    projection: ``tol_m`` is the largest distance between the inner and outer approximations.
    ``warm``: the LPs re-solved on one HiGHS model (:class:`_WarmLP`, with a scipy of
    :data:`WARM_LP_SCIPY`); False: each by ``linprog``.

    Raises InfeasibleError when no CoM position is in equilibrium (e.g. one contact too steep).
    """
    A, b = _equilibrium_system(patches)
    n = A.shape[1]
    A_load, b_load = _load_rows(patches)
    A_ub = np.hstack((A_load, np.zeros((A_load.shape[0], 2)))) if A_load.shape[0] else None
    b_ub = b_load if A_load.shape[0] else None
    corners = np.vstack([np.asarray(p.corners_world, dtype=float) for p in patches])
    centre = corners[:, :2].mean(axis=0)
    bounds = [(0.0, None)] * (n - 2) + [
        (centre[0] - REGION_BOUND_M, centre[0] + REGION_BOUND_M),
        (centre[1] - REGION_BOUND_M, centre[1] + REGION_BOUND_M),
    ]
    lps = 0
    solve = _WarmLP(A, b, A_ub, b_ub, bounds) if _highs is not None and warm else None

    def extreme(direction: np.ndarray) -> np.ndarray | None:
        nonlocal lps
        lps += 1
        cost = np.zeros(n)
        cost[-2:] = -direction
        if solve is not None:
            return solve(cost)
        res = linprog(cost, A_ub=A_ub, b_ub=b_ub, A_eq=A, b_eq=b, bounds=bounds, method="highs")
        return None if res.status != 0 else res.x[-2:]

    vertices = []
    for angle in (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0):
        v = extreme(np.array([math.cos(angle), math.sin(angle)]))
        if v is None:
            raise InfeasibleError("the contacts cannot balance gravity for any centre of mass position")
        vertices.append(v)
    done: set[tuple[float, float, float, float]] = set()
    while lps < max_lps:
        points = np.array(vertices)
        hull = convex_hull_indices(points)
        polygon = points[hull]
        if polygon.shape[0] < 3:
            return polygon  # a segment or a point: degenerate (e.g. one point contact)
        grown = False
        for i in range(polygon.shape[0]):
            a, c = polygon[i], polygon[(i + 1) % polygon.shape[0]]
            key = (round(a[0], 6), round(a[1], 6), round(c[0], 6), round(c[1], 6))
            if key in done:
                continue
            edge = c - a
            normal = np.array([edge[1], -edge[0]]) / max(np.linalg.norm(edge), 1e-12)  # outward (CCW)
            v = extreme(normal)
            if v is not None and normal.dot(v - a) > tol_m:
                vertices.append(v)
                grown = True
            else:
                done.add(key)
            if lps >= max_lps:
                break
        if not grown:
            break
    points = np.array(vertices)
    return points[convex_hull_indices(points)]


def is_statically_stable(
    patches: Sequence[ContactPatch], com_world: np.ndarray, tol: float = 1e-6
) -> tuple[bool, float]:
    """Whether forces in the linearized cones balance gravity with the CoM at ``com_world``: the QP
    min ||lambda||^2 s.t. A_f lambda = b - A_c c, lambda >= 0 (and the patches' load bounds) solved
    with proxsuite (§2.2). Returns (feasible, primal residual of the equalities and load bounds per unit
    weight)."""
    _forces, residual = equilibrium_forces(patches, com_world)
    return residual < max(tol, 1e-4), residual


def equilibrium_forces(patches: Sequence[ContactPatch], com_world: np.ndarray) -> tuple[np.ndarray, float]:
    """The force QP of :func:`is_statically_stable`: (the lambdas per unit weight, in
    ``_equilibrium_system``'s column order, and the residual of the equalities and load bounds)."""
    A, b = _equilibrium_system(patches)
    A_f, A_c = A[:, :-2], A[:, -2:]
    rhs = b - A_c.dot(np.asarray(com_world, dtype=float)[:2])
    n = A_f.shape[1]
    A_load, b_load = _load_rows(patches)
    C = np.vstack((np.eye(n), A_load))
    lower = np.zeros(C.shape[0])
    upper = np.concatenate((np.full(n, 1e20), b_load))
    qp = proxsuite.proxqp.dense.QP(n, A_f.shape[0], C.shape[0])
    qp.settings.eps_abs = 1e-9
    qp.settings.verbose = False
    qp.init(np.eye(n), np.zeros(n), A_f, rhs, C, lower, upper)
    qp.solve()
    lam = np.maximum(qp.results.x, 0.0)
    excess = np.maximum(A_load.dot(lam) - b_load, 0.0) if b_load.size else np.zeros(0)
    residual = float(np.linalg.norm(np.concatenate((A_f.dot(lam) - rhs, excess))))
    return lam, residual
