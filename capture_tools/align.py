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
    pts = np.stack([(u - depth_k.cx) / depth_k.fx * z, (v - depth_k.cy) / depth_k.fy * z, z], axis=1)
    pc = pts @ depth_to_colour[:3, :3].T + depth_to_colour[:3, 3]
    zc = pc[:, 2]
    ok = zc > 1e-6
    uc = np.round(colour_k.fx * pc[ok, 0] / zc[ok] + colour_k.cx).astype(np.int64)
    vc = np.round(colour_k.fy * pc[ok, 1] / zc[ok] + colour_k.cy).astype(np.int64)
    zc = zc[ok]
    inside = (uc >= 0) & (vc >= 0) & (uc < colour_k.width) & (vc < colour_k.height)
    uc, vc, zc = uc[inside], vc[inside], zc[inside]
    out = np.zeros((colour_k.height, colour_k.width), np.float32)
    order = np.argsort(-zc)  # far first: nearer points overwrite them (z-buffer)
    out[vc[order], uc[order]] = zc[order]
    return out
