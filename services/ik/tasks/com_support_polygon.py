"""CoM projection inside the support polygon with a margin (eq. 11 of the footstep paper)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import frame_id, frame_jacobian
from services.ik.task import Task
from services.model.ground import convex_hull_indices

_ROT90 = np.array([[0.0, -1.0], [1.0, 0.0]])


class ComSupportPolygonTask(Task):
    """Keep C, the ground projection of the CoM, at least ``margin_m`` inside the support polygon.

    For an edge from P1 to P2 of the counter-clockwise polygon with inward normal n, eq. (11)::

        -<d(PC)/dt | n> <= lambda (<PC | n> - d)

    is the inequality form (4) of G = d - <PC | n> <= 0, one row per edge *directly facing* C (the
    foot of the perpendicular from C lies on the edge), plus every edge already violated (C outside
    or within the margin); ``all_edges=True`` keeps every edge.

    The polygon is either fixed, ``polygon_world_xy`` (k x 2 [m], any vertex order, convex hull
    taken), or attached to the robot: the convex hull of the corners of rectangular soles
    ``sole_frames`` of size ``sole_size_m`` (length along the sole x, width along y) [m], recomputed
    at every iteration with the motion of its vertices in the Jacobian (footstep planning moves the
    feet while the CoM must stay over them).
    """

    needs_com = True

    def __init__(
        self,
        model: pin.Model,
        margin_m: float,
        polygon_world_xy: np.ndarray | None = None,
        sole_frames: Sequence[str] = (),
        sole_size_m: tuple[float, float] | None = None,
        all_edges: bool = False,
        gain: float = 1.0,
        name: str = "com_in_support_polygon",
    ) -> None:
        super().__init__(name, gain, lower=-np.inf, upper=0.0)
        self.model = model
        self.margin_m = float(margin_m)
        self.all_edges = all_edges
        if (polygon_world_xy is None) == (len(sole_frames) == 0):
            raise InvalidRequestError(
                f"task {name!r}: give either polygon_world_xy (fixed polygon) or sole_frames + sole_size_m"
            )
        self.polygon_world_xy: np.ndarray | None = None
        self.sole_frame_ids: list[int] = []
        if polygon_world_xy is not None:
            self.set_polygon(polygon_world_xy)
        else:
            if sole_size_m is None or len(sole_size_m) != 2 or min(sole_size_m) <= 0.0:
                raise InvalidRequestError(f"task {name!r}: sole_size_m must be (length, width) > 0 [m]")
            self.sole_frame_ids = [frame_id(model, f) for f in sole_frames]
            half_l, half_w = 0.5 * float(sole_size_m[0]), 0.5 * float(sole_size_m[1])
            self.sole_corners_m = np.array(
                [
                    [half_l, half_w, 0.0],
                    [-half_l, half_w, 0.0],
                    [-half_l, -half_w, 0.0],
                    [half_l, -half_w, 0.0],
                ]
            )

    def set_polygon(self, polygon_world_xy: np.ndarray) -> None:
        """Replace the fixed polygon (k x 2 [m]); its convex hull is used."""
        points = np.asarray(polygon_world_xy, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2 or points.shape[0] < 3 or not np.all(np.isfinite(points)):
            raise InvalidRequestError(
                f"task {self.name!r}: polygon_world_xy must be k >= 3 finite (x, y) rows"
            )
        hull = convex_hull_indices(points)
        if hull.shape[0] < 3:
            raise InvalidRequestError(f"task {self.name!r}: the support polygon is degenerate (zero area)")
        self.polygon_world_xy = points[hull]
        normals, offsets, tangents, starts, lengths = _edges(self.polygon_world_xy)
        stacked = np.vstack((normals, tangents))
        self._fixed = (normals, stacked, np.concatenate((offsets, starts)), lengths, normals.shape[0])

    def current_polygon(self, data: pin.Data) -> np.ndarray:
        """Counter-clockwise support polygon (k x 2 [m]) in the state held by ``data``."""
        if self.polygon_world_xy is not None:
            return self.polygon_world_xy
        points = self._sole_corners(data)
        return points[convex_hull_indices(points[:, :2]), :2]

    def _sole_corners(self, data: pin.Data) -> np.ndarray:
        """World corners of every sole (4 per sole frame, 3-D) [m]."""
        return self._sole_corners_and_origins(data)[0]

    def _sole_corners_and_origins(self, data: pin.Data) -> tuple[np.ndarray, list[np.ndarray]]:
        """World corners of every sole (4 per sole frame, 3-D) [m], and the sole frames' origins."""
        oMf = data.oMf
        placements = [oMf[fid] for fid in self.sole_frame_ids]
        origins = [T.translation for T in placements]
        corners = self.sole_corners_m
        return np.concatenate(
            [o + corners.dot(T.rotation.T) for o, T in zip(origins, placements, strict=True)]
        ), origins

    def _vertex_jacobians(
        self, data: pin.Data, points: np.ndarray, origins: list[np.ndarray], vertices: np.ndarray
    ) -> np.ndarray:
        """(len(vertices), 2, nv) Jacobians of the ground projections of the sole corners
        ``points[vertices]`` (corner k on sole k // 4): v_p = v_o + w x (p - o)."""
        sole = vertices // 4
        J = np.array([frame_jacobian(self.model, data, fid) for fid in self.sole_frame_ids])[sole]
        r = points[vertices] - np.array(origins)[sole]
        out = np.empty((vertices.shape[0], 2, self.model.nv))
        out[:, 0] = J[:, 0] + r[:, 2:3] * J[:, 4] - r[:, 1:2] * J[:, 5]
        out[:, 1] = J[:, 1] - r[:, 2:3] * J[:, 3] + r[:, 0:1] * J[:, 5]
        return out

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        c = data.com[0][:2]
        if self.polygon_world_xy is not None:
            # [<PC | n>; L x the foot of the perpendicular along the edge] in one product
            normals, stacked, shifts, lengths, k = self._fixed
            projections = stacked.dot(c) - shifts
            G = self.margin_m - projections[:k]
            along = projections[k:]
            keep = ((along >= 0.0) & (along <= lengths)) | (G > 0.0)
            if self.all_edges:
                return G, -normals.dot(data.Jcom[:2])
            return G[keep], -normals[keep].dot(data.Jcom[:2])
        points, origins = self._sole_corners_and_origins(data)
        hull = convex_hull_indices(points[:, :2])
        polygon = points[hull, :2]
        normals, offsets, tangents, starts, lengths = _edges(polygon)
        G = self.margin_m - (normals.dot(c) - offsets)
        along = tangents.dot(c) - starts
        rows = np.flatnonzero(self.all_edges | ((along >= 0.0) & (along <= lengths)) | (G > 0.0))
        # The vertices move with the soles:
        # d<PC|n> = n^T (dC - dP1) + (C - P1)^T Rot90 (I - t t^T) / L (dP2 - dP1).
        J_vertices = self._vertex_jacobians(data, points, origins, hull)
        i, j = rows, (rows + 1) % hull.shape[0]
        n, t = normals[i], tangents[i]
        a = (c - polygon[i]).dot(_ROT90)
        dn = (a - np.einsum("rk,rk->r", a, t)[:, None] * t) / lengths[i][:, None]
        dG = -(n.dot(data.Jcom[:2])) + np.einsum("rk,rkv->rv", n, J_vertices[i])
        dG -= np.einsum("rk,rkv->rv", dn, J_vertices[j] - J_vertices[i])
        return G[rows], dG


def _edges(polygon: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per edge of a counter-clockwise polygon: inward normals n, offsets <n, P1>, unit tangents t,
    <t, P1> and lengths, so that <PC | n> = n.c - offset and the foot of the perpendicular is at
    (t.c - <t, P1>) / L along the edge."""
    edges = np.concatenate((polygon[1:], polygon[:1])) - polygon
    lengths = np.sqrt(np.einsum("ij,ij->i", edges, edges))
    tangents = edges / lengths[:, None]
    normals = tangents @ _ROT90.T  # inward for a counter-clockwise polygon
    offsets = np.einsum("ij,ij->i", normals, polygon)
    starts = np.einsum("ij,ij->i", tangents, polygon)
    return normals, offsets, tangents, starts, lengths
