"""Compare estimated camera poses with reference poses: similarity alignment and per-view errors.

Frames: both pose sets are (N, 4, 4) camera-to-world, OpenCV axes. The similarity (s, R, t) maps the
estimated frame onto the reference frame and is fitted to the camera centres (Umeyama's least
squares); rotation errors are geodesic angles between aligned and reference camera rotations.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rsart.errors import RsartError


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R (3, 3), t (3,)) minimising Σ‖dst_i − (s R src_i + t)‖² for (N, 3) point sets (N ≥ 3).

    Hand-written (a dozen lines) because open3d/scipy expose it only for point clouds with their own types.
    """
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    if len(src) < 3 or src.shape != dst.shape:
        raise RsartError(f"similarity alignment needs >= 3 matched points, got {len(src)} and {len(dst)}")
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    var = (a ** 2).sum() / len(src)
    s = float(np.trace(np.diag(S) @ D) / var) if with_scale and var > 0 else 1.0
    return s, R, md - s * R @ ms


def apply_similarity(c2w: np.ndarray, s: float, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 4, 4) cameras moved by x -> s R x + t (rotations stay orthonormal: the scale moves centres only)."""
    out = np.array(c2w, dtype=float, copy=True)
    out[:, :3, :3] = R @ out[:, :3, :3]
    out[:, :3, 3] = (s * (R @ out[:, :3, 3].T)).T + t
    return out


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """(N,) geodesic angles in degrees between (N, 3, 3) rotation stacks."""
    d = np.einsum("nij,nik->njk", Ra, Rb)
    c = np.clip((np.trace(d, axis1=1, axis2=2) - 1) / 2, -1, 1)
    return np.degrees(np.arccos(c))


@dataclass
class PoseErrors:
    """Per-view errors after alignment: rotation (degrees), translation (metres / scene units)."""

    rot_deg: np.ndarray
    trans: np.ndarray
    scale: float

    @property
    def median_rot_deg(self) -> float:
        return float(np.median(self.rot_deg))

    @property
    def median_trans(self) -> float:
        return float(np.median(self.trans))

    def to_dict(self) -> dict:
        return {"views": int(len(self.rot_deg)), "median_rot_deg": self.median_rot_deg,
                "max_rot_deg": float(np.max(self.rot_deg)), "median_trans": self.median_trans,
                "max_trans": float(np.max(self.trans)), "similarity_scale": self.scale}


def pose_errors(est: np.ndarray, ref: np.ndarray, align: str = "sim3") -> PoseErrors:
    """Errors of (N, 4, 4) ``est`` against ``ref``; ``align`` = "sim3" | "se3" | "none" (already in one frame)."""
    est, ref = np.asarray(est, float), np.asarray(ref, float)
    if align == "none":
        s, R, t = 1.0, np.eye(3), np.zeros(3)
    elif align in ("sim3", "se3"):
        s, R, t = umeyama(est[:, :3, 3], ref[:, :3, 3], with_scale=align == "sim3")
    else:
        raise RsartError(f"alignment {align!r} is not sim3, se3 or none")
    a = apply_similarity(est, s, R, t)
    return PoseErrors(rotation_angle_deg(a[:, :3, :3], ref[:, :3, :3]),
                      np.linalg.norm(a[:, :3, 3] - ref[:, :3, 3], axis=1), s)
