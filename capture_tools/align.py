"""Depth-to-colour alignment: re-project a depth image into the colour camera (what librealsense's
``rs2::align`` does), with a z-buffer so the nearest surface wins where several depth pixels land.

Frames: ``depth_to_colour`` (4, 4) maps depth-camera points (OpenCV axes, metres) to colour-camera
points. Hand-written (20 lines of numpy) because OpenCV's rgbd module is not in opencv-contrib 5.
"""
from __future__ import annotations

import numpy as np

from rsart.camera import Intrinsics


def align_depth_to_colour(depth: np.ndarray, depth_k: Intrinsics, colour_k: Intrinsics,
                          depth_to_colour: np.ndarray) -> np.ndarray:
    """(Hc, Wc) float32 colour-aligned z-depth (metres, 0 = none) from a (Hd, Wd) depth image in metres."""
    h, w = depth.shape
    v, u = np.nonzero(depth > 0)
    z = depth[v, u].astype(np.float64)
    pts = depth_k.unproject(u, v, z)
    pc = pts @ depth_to_colour[:3, :3].T + depth_to_colour[:3, 3]
    ok = pc[:, 2] > 1e-6
    uv, zc = colour_k.project(pc[ok])
    uc, vc = np.round(uv[:, 0]).astype(np.int64), np.round(uv[:, 1]).astype(np.int64)
    inside = (uc >= 0) & (vc >= 0) & (uc < colour_k.width) & (vc < colour_k.height)
    uc, vc, zc = uc[inside], vc[inside], zc[inside]
    out = np.zeros((colour_k.height, colour_k.width), np.float32)
    order = np.argsort(-zc)  # far first: nearer points overwrite them (z-buffer)
    out[vc[order], uc[order]] = zc[order]
    return out
