"""The one camera model of rsart (DESIGN.md §3).

Convention: OpenCV camera axes (x right, y down, z forward). Extrinsics are
camera-to-world 4x4 matrices ``c2w`` mapping camera-frame points (metres) to the
world (object base) frame. Pixel (u, v) = (0, 0) is the *centre* of the top-left
pixel, so ``cx = (width - 1) / 2`` centres the principal point.
Converters to the OpenGL/Blender/nerfstudio convention (x right, y up, z backward)
live here and nowhere else.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Flip between OpenCV and OpenGL camera axes: c2w_gl = c2w_cv @ CV_TO_GL (and back, it is its own inverse).
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels; ``distortion`` is OpenCV's (k1, k2, p1, p2[, k3...]) or None."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] | None = None

    @property
    def K(self) -> np.ndarray:
        """(3, 3) float64 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, width: int, height: int) -> "Intrinsics":
        """Intrinsics of the same camera resampled to ``width`` x ``height`` (pixel-centre convention kept)."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(width, height, self.fx * sx, self.fy * sy,
                          (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5, self.distortion)

    @staticmethod
    def from_fov(width: int, height: int, fov_y_deg: float) -> "Intrinsics":
        """Square-pixel intrinsics with a vertical field of view in degrees, principal point centred."""
        f = 0.5 * height / np.tan(np.deg2rad(fov_y_deg) / 2)
        return Intrinsics(width, height, float(f), float(f), (width - 1) / 2, (height - 1) / 2)

    def project(self, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) camera-frame points (OpenCV axes, metres) -> (N, 2) pixel coords (u, v) and (N,) depth z.

        Distortion is ignored. Points at z = 0 give inf/NaN pixels, as numpy divides (no warning).
        """
        return pinhole_project(self.K, np.asarray(points_cam, dtype=np.float64).reshape(-1, 3))

    def unproject(self, u: np.ndarray, v: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(N, 3) camera-frame points (metres) of pixels (u, v) (each (N,)) at z-depth ``z`` (N,) metres."""
        return pinhole_unproject(self.K, u, v, z)

    def directions(self) -> np.ndarray:
        """(H, W, 3) float64 camera-frame rays through every pixel centre, scaled to z = 1."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        return pinhole_unproject(self.K, u, v, np.ones_like(u))

    def to_dict(self) -> dict:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy,
                "distortion": list(self.distortion) if self.distortion is not None else None}


#: Colour stream of an Intel RealSense D435 at 640x480 (typical factory calibration, ~69.4° x 42.5° FOV).
REALSENSE_D435_COLOR_640x480 = Intrinsics(640, 480, 615.0, 615.0, 319.5, 239.5)


@dataclass(frozen=True)
class Camera:
    """A posed pinhole camera: intrinsics + ``c2w`` (4, 4) camera-to-world, OpenCV axes, metres."""

    intrinsics: Intrinsics
    c2w: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        object.__setattr__(self, "c2w", np.asarray(self.c2w, dtype=np.float64).reshape(4, 4))

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix."""
        return self.intrinsics.K

    @property
    def w2c(self) -> np.ndarray:
        """(4, 4) world-to-camera (OpenCV axes)."""
        R, t = self.c2w[:3, :3], self.c2w[:3, 3]
        out = np.eye(4)
        out[:3, :3] = R.T
        out[:3, 3] = -R.T @ t
        return out

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in the world frame."""
        return self.c2w[:3, 3].copy()

    @property
    def width(self) -> int:
        return self.intrinsics.width

    @property
    def height(self) -> int:
        return self.intrinsics.height

    def c2w_opengl(self) -> np.ndarray:
        """(4, 4) camera-to-world in the OpenGL/Blender/nerfstudio convention (y up, z backward)."""
        return self.c2w @ CV_TO_GL

    @staticmethod
    def from_opengl(intrinsics: Intrinsics, c2w_gl: np.ndarray) -> "Camera":
        """Build a camera from an OpenGL/Blender camera-to-world matrix."""
        return Camera(intrinsics, np.asarray(c2w_gl, dtype=np.float64) @ CV_TO_GL)

    def scaled(self, width: int, height: int) -> "Camera":
        """The same pose with intrinsics resampled to a new image size."""
        return Camera(self.intrinsics.scaled(width, height), self.c2w)

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project (N, 3) world points; returns (N, 2) pixel coords (u, v) and (N,) camera-frame depth z (m).

        Distortion is ignored (rsart renders undistorted images).
        """
        p = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        return self.intrinsics.project(p @ self.w2c[:3, :3].T + self.w2c[:3, 3])

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Rays through every pixel centre: origins (H, W, 3) and directions (H, W, 3), world frame.

        Directions are scaled so that their camera-frame z component is 1 (a ray parameter
        t is then the pixel's z-depth, as depth images store it).
        """
        d_world = self.intrinsics.directions() @ self.c2w[:3, :3].T
        o = np.broadcast_to(self.c2w[:3, 3], d_world.shape).copy()
        return o, d_world

    def backproject(self, depth: np.ndarray) -> np.ndarray:
        """Back-project a (H, W) z-depth map (metres, 0 = none) to (M, 3) world points of the valid pixels."""
        o, d = self.rays()
        valid = depth > 0
        return o[valid] + d[valid] * depth[valid][:, None]


def pinhole_project(K, points_cam):
    """Pinhole projection with a (3, 3) matrix ``K``: (..., 3) camera-frame points (OpenCV, metres) ->
    ((..., 2) pixel coords (u, v), (...) z-depth).

    ``K`` and the points are numpy arrays, or torch tensors (then the result is a tensor and
    differentiable, as pd2gs needs). Pixel (0, 0) is the centre of the top-left pixel.
    """
    x, y, z = points_cam[..., 0], points_cam[..., 1], points_cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K[0, 0] * x / z + K[0, 2]
        v = K[1, 1] * y / z + K[1, 2]
    return _stack([u, v]), z


def pinhole_unproject(K, u, v, z):
    """Inverse of :func:`pinhole_project`: pixel coords ``u``, ``v`` and z-depth ``z`` (metres; arrays of one
    shape S) -> (S..., 3) camera-frame points. numpy arrays, or torch tensors (differentiable)."""
    x = (u - K[0, 2]) / K[0, 0] * z
    y = (v - K[1, 2]) / K[1, 1] * z
    return _stack([x, y, z])


def _stack(cols: list):
    """Stack along a new last axis, in numpy or torch as the inputs are."""
    if isinstance(cols[0], np.ndarray) or np.isscalar(cols[0]):
        return np.stack(cols, axis=-1)
    import torch  # only reached with tensors, so rsart's core needs no torch

    return torch.stack(cols, dim=-1)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = np.array([0.0, 0.0, 1.0])) -> np.ndarray:
    """(4, 4) OpenCV camera-to-world looking from ``eye`` at ``target`` with world ``up`` appearing upward."""
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:  # looking straight along up: pick any perpendicular
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, eye
    return c2w


def corner_origin_intrinsics(K: Intrinsics) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) with the centre of pixel (0, 0) at (0.5, 0.5), as COLMAP, nerfstudio and Blender
    readers put it (rsart puts it at (0, 0)): ``cx + 0.5, cy + 0.5``; focal lengths unchanged."""
    return K.fx, K.fy, K.cx + 0.5, K.cy + 0.5


def horizontal_fov(K: Intrinsics) -> float:
    """Horizontal field of view in radians, ``2·atan(width / (2·fx))`` (Blender's ``camera_angle_x``)."""
    return 2.0 * math.atan(K.width / (2.0 * K.fx))
