"""Messages of the ``perception`` service (colour-histogram objects localized by stereo; vision/).

Frames: world (z up) [m]; the left camera's optical frame (x right, y down, z forward) [m]. Pixels:
(u, v) = (column, row) with pixel (row i, column j) centred at (j + 0.5, i + 0.5), as ``sim/render``
and the robot models' camera matrices. Configurations ``q`` follow the pinocchio layout of the robot
model (``[x, y, z, qx, qy, qz, qw, joints...]``).
"""

from __future__ import annotations

import msgspec
import numpy as np

from services.bus.limits import Budget, ImageSide, Name
from services.bus.schemas.rectangle import Rectangle
from services.bus.spec import EndpointSpec

# ---------------------------------------------------------------------------------------------- locate


class StereoImages(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A rectified stereo pair sent with the request instead of rendered by ``sim/render``."""

    left_rgb: np.ndarray  # (H, W, 3) uint8, RGB channel order (as sim/render)
    right_rgb: np.ndarray  # (H, W, 3) uint8, same size
    K: np.ndarray | None = None  # (3, 3) [px]; None: the robot model's camera scaled to the image size


class LocateRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Where is ``object``? The camera pose comes from the robot's kinematics at ``q``."""

    object: Name  # a learned object name (perception/models), e.g. "orange_ball"
    model: Name = ""  # robot model (services.model); "": the sim's model when q is None, else hrp2_like
    q: np.ndarray | None = None  # (nq,) robot configuration; None: the robot's current one (sim/state)
    camera: Name = "wide"  # stereo pair of the robot model: "wide" (0.144 m baseline) or "narrow"
    width_px: ImageSide = 640  # image size asked of sim/render (ignored when images are given)
    height_px: ImageSide = 480
    images: StereoImages | None = None  # None: the service renders the pair through sim/render
    method: Name = ""  # stereo estimator: "" (service default), "centroid", "bm", "sgbm" or "edges"
    # also report every other learned object seen in the same images (``LocateReply.others``: ~3-5 ms
    # per model more); False (the default): only ``object``. The supervisor's looks ask for it (the
    # balls beside the one to grasp go on its map), its survey does not (it asks for each object).
    others: bool = False
    # wall-clock budget [s] (<= 60); None: the service's time_budget_s. Past it: ``timeout`` naming the
    # stage reached (``details.stage``: the state, the render or the stereo localization).
    time_budget_s: Budget | None = None


class PixelBox(msgspec.Struct, kw_only=True, frozen=True):
    """CamShift's rotated rectangle in one image: centre, sides (4 std of the colour mass), angle."""

    u_px: float
    v_px: float
    width_px: float
    height_px: float
    angle_deg: float


#: ``details["reason"]`` of ``perception/locate``'s ``not_found`` replies (sub-reasons across processes).
REASON_NOT_IN_VIEW = "not_in_view"  # not in the left image
REASON_NOT_IN_RIGHT_VIEW = "not_in_right_view"
REASON_NO_DISPARITY = "no_disparity"
REASON_STEREO_MISMATCH = "stereo_mismatch"
REASON_AMBIGUOUS = "ambiguous"
#: seen in the left image next to the robot's own arm and not matched in the right one: the arm hides it
#: (move the arm out of the view and look again)
REASON_HIDDEN_BY_OWN_BODY = "hidden_by_own_body"
#: The reasons another viewpoint may fix (the supervisor then looks around).
VIEWPOINT_REASONS = (
    REASON_NOT_IN_VIEW,
    REASON_NOT_IN_RIGHT_VIEW,
    REASON_NO_DISPARITY,
    REASON_STEREO_MISMATCH,
    REASON_AMBIGUOUS,
    REASON_HIDDEN_BY_OWN_BODY,
)


class FootprintMsg(msgspec.Struct, kw_only=True, frozen=True):
    """An object's rectangle on the floor from the stereo points of its silhouette's outline
    (vision/footprint.py): what navigation needs of a box, a table or a chair."""

    center: list[float]  # (x, y) world [m]
    size: list[float]  # (length along yaw, width) [m]
    yaw: float  # [rad], in (-pi/2, pi/2]
    top_z: float  # its top: the highest height many outline points share, world [m]
    n_points: int  # outline points it was fitted to
    # outline edges left out next to an occluder (another object, the robot's own body): not seen
    n_hidden: int = 0

    @property
    def rectangle(self) -> Rectangle:
        """The footprint as the stack's rectangle (world [m, rad])."""
        centre = (float(self.center[0]), float(self.center[1]))
        return Rectangle(centre, (float(self.size[0]), float(self.size[1])), float(self.yaw))


class SeenObject(msgspec.Struct, kw_only=True, frozen=True):
    """Another learned object seen in the images of a ``locate`` (in passing: no footprint; ask for it
    to get one). Fields as in :class:`LocateReply`."""

    object: str
    position: list[float]  # world [m]: a ball's centre, the middle of another object's silhouette
    distance_m: float  # from the left camera [m]
    size_m: list[float]  # (width, height) of its CamShift box at its depth [m]
    confidence: float  # in [0, 1]
    method: str  # stereo estimator used
    box_left: PixelBox


class LocateReply(msgspec.Struct, kw_only=True, frozen=True):
    """A localized object.

    ``position`` is the object's centre for ball models (shape "sphere"), the triangulated centre of
    the coloured silhouette otherwise (a point on the visible middle of a box or table).
    """

    object: str
    position: list[float]  # world [m]
    position_camera: list[float]  # left camera optical frame [m]
    distance_m: float  # from the left camera [m]
    size_m: list[float]  # (width, height) of the CamShift box at the object's depth [m]
    confidence: float  # in [0, 1]: colour typicality x fill of the CamShift ellipse (min of both images)
    method: str  # stereo estimator used: "centroid", "bm", "sgbm" or "edges" (fallbacks, see vision)
    disparity_px: float  # u_left - u_right [px]
    box_left: PixelBox
    box_right: PixelBox
    window_left: list[int]  # [x, y, width, height] [px], the left measurement window
    camera: str  # stereo pair used
    T_world_camera: list[list[float]]  # 4x4 pose of the left optical frame used (from q)
    rendered: bool  # the images came from sim/render (else from the request)
    sim_time_s: float  # sim time of the rendered images [s] (0 when the images came with the request)
    footprint: FootprintMsg | None = None  # non-spherical objects not cut by a side or top border
    # the other learned objects seen in the same images (request ``others``), most confident first;
    # one object per region: vision.localize.others_in_frame says how identities are kept apart
    others: list[SeenObject] = []


LOCATE = EndpointSpec(
    "perception",
    "locate",
    LocateRequest,
    LocateReply,
    "world position, size and confidence of a learned object seen by a head stereo pair; "
    "not_found says why (not_in_view, ambiguous, ...)",
)

# ---------------------------------------------------------------------------------------------- models


class ModelsRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """No fields."""


class ObjectModelInfo(msgspec.Struct, kw_only=True, frozen=True):
    name: str  # object name, e.g. "yellow_table"
    shape: str  # "sphere" (position = centre) or "blob"
    n_pixels: int  # coloured pixels the histogram was learned from
    source: str  # how it was learned


class ModelsReply(msgspec.Struct, kw_only=True, frozen=True):
    names: list[str]  # sorted
    objects: list[ObjectModelInfo]  # same order
    models_dir: str  # where the service loaded them from


MODELS = EndpointSpec(
    "perception", "models", ModelsRequest, ModelsReply, "the objects perception knows (learned colour models)"
)


class LookAroundRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """The look-around plan of a robot model's stereo pair ``camera`` (services/perception/look_around.py)."""

    model: Name = ""  # "" = the service's robot model
    camera: Name = "wide"


class LookAroundReply(msgspec.Struct, kw_only=True, frozen=True):
    """How the head moves the pair's gaze and where to look: ``head_pan_joint`` (turns the gaze sideways)
    and ``head_tilt_joint`` with their [lower, upper] limits [rad] and ``tilt_sign`` (+1: increasing the
    tilt joint lowers the gaze); ``views``: head [pan, tilt] joint values [rad] to visit in order (rows
    of pan at a few gaze depressions); ``turns_rad``: body yaw offsets from the heading at the start of
    a search, each followed by a scan, so that together they see all around; ``image_size_px``: [width,
    height] of the pair's images."""

    head_pan_joint: str
    head_tilt_joint: str
    pan_limits_rad: list[float]
    tilt_limits_rad: list[float]
    tilt_sign: float
    views: list[list[float]]
    turns_rad: list[float]
    image_size_px: list[int]


LOOK_AROUND = EndpointSpec(
    "perception",
    "look_around",
    LookAroundRequest,
    LookAroundReply,
    "the head joints and the views (head pan/tilt, then body turns) that look all around for an object",
)
