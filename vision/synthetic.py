"""A small ray caster for synthetic test images with exact ground truth.

Every pixel casts a ray through its centre (``supersample`` x ``supersample`` rays per pixel, averaged, so
edges are anti-aliased like a real camera's) against spheres, yawed boxes and infinite textured planes,
then shades the nearest hit with a Lambertian model (ambient + directional light, no shadows). Object
surfaces carry a solid texture that modulates brightness only (the hue and saturation of an object stay
those of its albedo; a uniformly scaled BGR keeps HSV hue and saturation), planes carry a tiled
colour-noise texture so dense stereo has something to correlate. Gaussian sensor noise is added last.

Used by the tests and by ``scripts/bench.d/perception.py``; nothing here is needed at run time.
World frame: z up, metres. Cameras are given by ``T_world_camera`` (optical frame, see vision.camera).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import cv2
import numpy as np

from vision.camera import CameraIntrinsics, StereoRig, look_at, transform_points

BGR = tuple[float, float, float]


@dataclass(frozen=True)
class Sphere:
    """A ball: centre [m] in the world frame, radius [m], albedo BGR in 0..255."""

    name: str
    centre_world: tuple[float, float, float]
    radius_m: float
    bgr: BGR
    texture_amplitude: float = 0.12


@dataclass(frozen=True)
class Box:
    """A box rotated by ``yaw_rad`` about the world z axis: centre [m], half extents [m], albedo BGR."""

    name: str
    centre_world: tuple[float, float, float]
    half_extents_m: tuple[float, float, float]
    bgr: BGR
    yaw_rad: float = 0.0
    texture_amplitude: float = 0.12


@dataclass(frozen=True)
class Plane:
    """An infinite plane through ``point_world`` with normal ``normal_world``, tiled colour-noise texture."""

    name: str
    point_world: tuple[float, float, float]
    normal_world: tuple[float, float, float]
    bgr: BGR
    texture_amplitude: float = 0.35
    texture_scale_m: float = 0.5
    texture_seed: int = 0


@dataclass(frozen=True)
class Light:
    """Directional light: ``direction_world`` points towards the light; shade = ambient + diffuse * cos."""

    direction_world: tuple[float, float, float] = (0.3, -0.4, 1.0)
    ambient: float = 0.45
    diffuse: float = 0.6


Primitive = Sphere | Box | Plane


@dataclass(frozen=True)
class Scene:
    """Primitives (their index is the label in :class:`Render.labels`), light and sky colour."""

    primitives: tuple[Primitive, ...]
    light: Light = field(default_factory=Light)
    sky_bgr: BGR = (200.0, 190.0, 185.0)

    def mask_of(self, labels: np.ndarray, name: str) -> np.ndarray:
        """Boolean mask of the pixels of ``labels`` (from :class:`Render`) showing the object ``name``
        (every primitive of that name, e.g. a table top and its legs)."""
        ids = [i for i, p in enumerate(self.primitives) if p.name == name]
        if not ids:
            raise KeyError(f"no primitive {name!r}; have {sorted({p.name for p in self.primitives})}")
        return np.isin(labels, ids)


@dataclass(frozen=True)
class Render:
    """A rendered image (H x W x 3 BGR uint8) and per-pixel labels (index of the primitive seen at the
    pixel centre, -1 for the sky)."""

    image_bgr: np.ndarray
    labels: np.ndarray


@functools.lru_cache(maxsize=16)
def _plane_texture(seed: int, size: int = 256) -> np.ndarray:
    """A tileable multi-scale colour noise texture (size x size x 3 float32 in about [-1, 1])."""
    rng = np.random.default_rng(seed)
    tex = np.zeros((size, size, 3), np.float32)
    for cells, weight in ((4, 1.0), (16, 0.6), (64, 0.45), (256, 0.35)):
        coarse = rng.uniform(-1.0, 1.0, (cells, cells, 3)).astype(np.float32)
        # Wrap-padded cubic upsampling keeps the texture tileable.
        pad = np.pad(coarse, ((2, 2), (2, 2), (0, 0)), mode="wrap")
        step = size // cells
        up = cv2.resize(pad, ((cells + 4) * step, (cells + 4) * step), interpolation=cv2.INTER_CUBIC)
        tex += weight * up[2 * step : 2 * step + size, 2 * step : 2 * step + size]
    return tex / np.abs(tex).max()


def _solid_texture(p: np.ndarray, seed: int) -> np.ndarray:
    """Brightness texture in about [-1, 1] at surface points ``p`` (N, 3) [m], fixed to the object."""
    rng = np.random.default_rng(seed)
    out = np.zeros(p.shape[0], np.float32)
    for _ in range(6):
        k = rng.normal(size=3)
        k *= rng.uniform(60.0, 250.0) / np.linalg.norm(k)  # spatial frequencies of 2.5 to 10 cm periods
        out += np.sin(p @ k.astype(np.float32) + rng.uniform(0, 2 * np.pi)).astype(np.float32)
    return out / 2.5


def _roi(prim: Primitive, o: np.ndarray, R: np.ndarray, intr: CameraIntrinsics, s: int, shape) -> tuple:
    """Conservative hi-res pixel slice (rows, cols) that can see ``prim`` (whole image when unsure)."""
    full = (slice(0, shape[0]), slice(0, shape[1]))
    if isinstance(prim, Plane):
        return full
    if isinstance(prim, Sphere):
        c, r = np.asarray(prim.centre_world), prim.radius_m
    else:
        c, r = np.asarray(prim.centre_world), float(np.linalg.norm(prim.half_extents_m))
    pc = R.T @ (c - o)
    if pc[2] - r < 0.05:
        return full
    us, vs = [], []
    for dx in (-r, r):
        for dz in (-r, r):
            us.append(intr.fx * (pc[0] + dx) / (pc[2] + dz) + intr.cx)
            vs.append(intr.fy * (pc[1] + dx) / (pc[2] + dz) + intr.cy)
    u0, u1 = (min(us) + 0.5) * s - 0.5 - 2, (max(us) + 0.5) * s - 0.5 + 2
    v0, v1 = (min(vs) + 0.5) * s - 0.5 - 2, (max(vs) + 0.5) * s - 0.5 + 2
    c0, c1 = max(0, int(np.floor(u0))), min(shape[1], int(np.ceil(u1)) + 1)
    r0, r1 = max(0, int(np.floor(v0))), min(shape[0], int(np.ceil(v1)) + 1)
    if c0 >= c1 or r0 >= r1:
        return None
    return (slice(r0, r1), slice(c0, c1))


def _box_rotation(prim: Box) -> np.ndarray:
    c, s = np.cos(prim.yaw_rad), np.sin(prim.yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], np.float32)


def _intersect(prim: Primitive, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Ray parameter t (inf = miss) of the first hit of rays ``o + t d`` (d: (..., 3)) on ``prim``."""
    if isinstance(prim, Sphere):
        oc = (o - np.asarray(prim.centre_world)).astype(np.float32)
        a = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
        b = d @ oc
        c0 = float(oc @ oc - prim.radius_m**2)
        disc = b * b - a * c0
        with np.errstate(invalid="ignore"):
            t = (-b - np.sqrt(disc)) / a
        return np.where((disc >= 0) & (t > 0), t, np.inf).astype(np.float32)
    if isinstance(prim, Box):
        Rb = _box_rotation(prim)
        ob = Rb.T @ (o - np.asarray(prim.centre_world)).astype(np.float32)
        db = d @ Rb  # rows: Rb^T d
        h = np.asarray(prim.half_extents_m, np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - ob) / db
            t2 = (h - ob) / db
        near, far = np.minimum(t1, t2), np.maximum(t1, t2)
        # Element-wise over the 3 slabs: much faster than reducing along a length-3 last axis.
        tmin = np.maximum(np.maximum(near[..., 0], near[..., 1]), near[..., 2])
        tmax = np.minimum(np.minimum(far[..., 0], far[..., 1]), far[..., 2])
        return np.where((tmax >= tmin) & (tmin > 0), tmin, np.inf).astype(np.float32)
    n = np.asarray(prim.normal_world, np.float32)
    n = n / np.linalg.norm(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (np.float32((np.asarray(prim.point_world) - o) @ n)) / (d @ n)
    return np.where(t > 0, t, np.inf).astype(np.float32)


def _normal(prim: Primitive, p: np.ndarray) -> np.ndarray:
    """Unit outward normals (N, 3) at surface points ``p`` (N, 3) of ``prim``."""
    if isinstance(prim, Sphere):
        return (p - np.asarray(prim.centre_world, np.float32)) / np.float32(prim.radius_m)
    if isinstance(prim, Box):
        Rb = _box_rotation(prim)
        q = (p - np.asarray(prim.centre_world, np.float32)) @ Rb  # box-frame coordinates
        rel = np.abs(q) / np.asarray(prim.half_extents_m, np.float32)
        axis = np.argmax(rel, axis=1)
        nb = np.zeros_like(q)
        nb[np.arange(len(q)), axis] = np.sign(q[np.arange(len(q)), axis])
        return nb @ Rb.T
    n = np.asarray(prim.normal_world, np.float32)
    return np.broadcast_to(n / np.linalg.norm(n), p.shape)


def _albedo(prim: Primitive, index: int, p: np.ndarray) -> np.ndarray:
    """Albedo (N, 3) in 0..255 at hit points ``p`` (N, 3)."""
    base = np.asarray(prim.bgr, np.float32)
    if isinstance(prim, Plane):
        n = np.asarray(prim.normal_world, float)
        n /= np.linalg.norm(n)
        e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        tex = _plane_texture(prim.texture_seed)
        size = tex.shape[0]
        q = p - np.asarray(prim.point_world, np.float32)
        mx = ((q @ e1.astype(np.float32)) / prim.texture_scale_m * size).astype(np.float32)
        my = ((q @ e2.astype(np.float32)) / prim.texture_scale_m * size).astype(np.float32)
        mx, my = np.mod(mx, size), np.mod(my, size)
        # remap needs 2-D maps shorter than 32767 per side: sample as rows of 4096.
        n_pts = mx.shape[0]
        rows = -(-n_pts // 4096)
        mxp = np.zeros(rows * 4096, np.float32)
        myp = np.zeros(rows * 4096, np.float32)
        mxp[:n_pts], myp[:n_pts] = mx, my
        sampled = cv2.remap(
            tex,
            mxp.reshape(rows, 4096),
            myp.reshape(rows, 4096),
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_WRAP,
        ).reshape(-1, 3)[:n_pts]
        return np.clip(base * (1.0 + prim.texture_amplitude * sampled), 0, 255)
    mod = 1.0 + prim.texture_amplitude * _solid_texture(
        p - np.asarray(prim.centre_world, np.float32), index + 1
    )
    return base[None, :] * mod[:, None]


def render(
    scene: Scene,
    intrinsics: CameraIntrinsics,
    T_world_camera: np.ndarray,
    supersample: int = 2,
    noise_sigma: float = 2.0,
    rng: np.random.Generator | None = None,
) -> Render:
    """Ray-cast ``scene`` seen from the camera at ``T_world_camera`` (4x4, optical frame).

    supersample: rays per pixel along each axis (anti-aliasing); noise_sigma: std of additive Gaussian
    sensor noise [grey levels] (needs ``rng``; 0 disables it).
    """
    s = int(supersample)
    H, W = intrinsics.height * s, intrinsics.width * s
    T = np.asarray(T_world_camera, float)
    R, o = T[:3, :3], T[:3, 3]
    # Hi-res sample (i, j) sits at pixel coordinate ((j + 0.5) / s - 0.5, (i + 0.5) / s - 0.5).
    u = ((np.arange(W, dtype=np.float32) + 0.5) / s - 0.5 - intrinsics.cx) / intrinsics.fx
    v = ((np.arange(H, dtype=np.float32) + 0.5) / s - 0.5 - intrinsics.cy) / intrinsics.fy
    d_cam = np.empty((H, W, 3), np.float32)
    d_cam[..., 0], d_cam[..., 1], d_cam[..., 2] = u[None, :], v[:, None], 1.0
    d = d_cam @ R.T.astype(np.float32)  # world-frame directions with unit optical-z component

    depth = np.full((H, W), np.inf, np.float32)
    labels = np.full((H, W), -1, np.int16)
    rois = [_roi(prim, o, R, intrinsics, s, (H, W)) for prim in scene.primitives]
    for i, prim in enumerate(scene.primitives):
        roi = rois[i]
        if roi is None:
            continue
        t = _intersect(prim, o, d[roi])
        closer = t < depth[roi]
        depth[roi][closer] = t[closer]
        labels[roi][closer] = i

    light = np.asarray(scene.light.direction_world, np.float32)
    light /= np.linalg.norm(light)
    img = np.empty((H * W, 3), np.float32)
    img[:] = np.asarray(scene.sky_bgr, np.float32)
    flat_labels, flat_depth, flat_d = labels.ravel(), depth.ravel(), d.reshape(-1, 3)
    for i, prim in enumerate(scene.primitives):
        idx = np.flatnonzero(flat_labels == i)
        if idx.size == 0:
            continue
        p = o.astype(np.float32) + flat_depth[idx][:, None] * flat_d[idx]
        shade = scene.light.ambient + scene.light.diffuse * np.clip(_normal(prim, p) @ light, 0.0, None)
        img[idx] = _albedo(prim, i, p) * shade[:, None]
    img = img.reshape(H, W, 3)
    if s > 1:
        img = cv2.resize(img, (intrinsics.width, intrinsics.height), interpolation=cv2.INTER_AREA)
    if noise_sigma > 0:
        if rng is None:
            raise ValueError("noise_sigma > 0 needs an rng (np.random.default_rng(seed))")
        img = img + rng.normal(0.0, noise_sigma, img.shape).astype(np.float32)
    image = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return Render(image, labels[s // 2 :: s, s // 2 :: s].copy())


def render_stereo(
    scene: Scene,
    rig: StereoRig,
    T_world_left_camera: np.ndarray,
    supersample: int = 2,
    noise_sigma: float = 2.0,
    rng: np.random.Generator | None = None,
) -> tuple[Render, Render]:
    """Left and right renders of a rectified pair (right camera at +baseline along the left x axis)."""
    T_world_right = np.asarray(T_world_left_camera, float) @ rig.T_left_right
    left = render(scene, rig.intrinsics, T_world_left_camera, supersample, noise_sigma, rng)
    right = render(scene, rig.intrinsics, T_world_right, supersample, noise_sigma, rng)
    return left, right


# Demo-object colours (BGR): the paper's "orange ball", "green box" and "yellow table".
ORANGE: BGR = (20.0, 110.0, 235.0)
GREEN: BGR = (60.0, 160.0, 40.0)
YELLOW: BGR = (30.0, 210.0, 225.0)
BALL_RADIUS_M = 0.05  # the sim's graspable ball (issue 3)


def room(floor_seed: int = 1, wall_seed: int = 2, wall_x_m: float = 5.0) -> tuple[Plane, Plane]:
    """A textured greyish floor (z = 0) and a back wall at ``x = wall_x_m``."""
    return (
        Plane("floor", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (120.0, 125.0, 135.0), 0.35, 0.6, floor_seed),
        Plane("wall", (wall_x_m, 0.0, 0.0), (-1.0, 0.0, 0.0), (170.0, 160.0, 150.0), 0.35, 0.8, wall_seed),
    )


def table(
    name: str,
    centre_xy: tuple[float, float],
    top_z_m: float,
    size_xy=(0.8, 0.6),
    yaw_rad=0.0,
    bgr: BGR = YELLOW,
) -> tuple[Box, ...]:
    """A table: a 3 cm top at height ``top_z_m`` [m] on four 4 cm legs, all of colour ``bgr``."""
    x, y = centre_xy
    hx, hy = size_xy[0] / 2, size_xy[1] / 2
    parts: list[Box] = [Box(name, (x, y, top_z_m - 0.015), (hx, hy, 0.015), bgr, yaw_rad)]
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    for sx in (-1, 1):
        for sy in (-1, 1):
            lx, ly = sx * (hx - 0.04), sy * (hy - 0.04)
            parts.append(
                Box(
                    name,
                    (x + c * lx - s * ly, y + s * lx + c * ly, (top_z_m - 0.03) / 2),
                    (0.02, 0.02, (top_z_m - 0.03) / 2),
                    bgr,
                    yaw_rad,
                )
            )
    return tuple(parts)


@dataclass(frozen=True)
class BallPlacement:
    """A synthetic stereo test case: the scene, the left camera pose and the ball centre [m] (world)."""

    scene: Scene
    T_world_left_camera: np.ndarray
    ball_centre_world: np.ndarray
    distance_m: float


def random_ball_placement(
    rng: np.random.Generator,
    rig: StereoRig,
    distance_m: float,
    margin_px: float = 12.0,
    with_distractors: bool = True,
) -> BallPlacement:
    """An orange ball (radius BALL_RADIUS_M) at ``distance_m`` [m] from the left camera centre, fully in
    both images, in a textured room; with distractors, it rests on a green box and a yellow table stands
    to one side (never between the camera and the ball).

    The head camera is at 1.2-1.4 m, pitched 10-30 deg down and yawed +-0.3 rad, like a standing robot's.
    """
    k = rig.intrinsics
    r = BALL_RADIUS_M
    for _ in range(1000):
        yaw, pitch = rng.uniform(-0.3, 0.3), rng.uniform(np.deg2rad(10), np.deg2rad(30))
        eye = np.array([0.0, rng.uniform(-0.2, 0.2), rng.uniform(1.2, 1.4)])
        fwd = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), -np.sin(pitch)])
        T = look_at(eye, eye + fwd)
        # A pixel for the ball centre such that its whole disc is inside both images.
        rho = k.fx * r / distance_m * 1.1 + margin_px
        d = rig.disparity_of_depth(distance_m)
        u = rng.uniform(rho + d, k.width - 1 - rho)
        v = rng.uniform(rho, k.height - 1 - rho)
        ray = np.array([(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0])
        c_cam = ray / np.linalg.norm(ray) * distance_m
        c = transform_points(T, c_cam)
        if c[2] < r + 0.02 or c[0] < 0.5 or c[0] > 4.5:
            continue
        prims: list[Primitive] = [*room(int(rng.integers(1 << 30)), int(rng.integers(1 << 30)))]
        prims.append(Sphere("orange_ball", tuple(c), r, ORANGE))
        if with_distractors:
            top = c[2] - r
            if 0.05 < top < eye[2] - 0.1:  # a box higher than the eye would hide the ball's bottom
                prims.append(Box("green_box", (c[0] + 0.05, c[1], top / 2), (0.15, 0.2, top / 2), GREEN, yaw))
            # The table stands beside the line of sight, 1 m to the left or right of the ball.
            side = rng.choice([-1.0, 1.0])
            tx, ty = c[0] + rng.uniform(0.0, 0.8), c[1] + side * rng.uniform(0.9, 1.4)
            prims.extend(table("yellow_table", (tx, ty), 0.7, yaw_rad=rng.uniform(-0.5, 0.5)))
        return BallPlacement(Scene(tuple(prims)), T, c, distance_m)
    raise RuntimeError("could not place the ball in view")
