"""RGB-D bundle adjustment: refine SfM poses and points with the sensor's depth at every keypoint.

Why: a small object filling part of the view leaves SfM with a near-ambiguity between rotating a
camera and sliding it sideways (both keep the object centred); on 320x240 booth captures that alone
costs ~0.5° and ~1 cm. A measured depth per keypoint pins every point's distance along its ray and
removes it. pycolmap's bundle adjuster has no depth term, so this one is written with
``scipy.optimize.least_squares`` (sparse Jacobian, robust loss).

Residuals per observation (camera i, point j, keypoint (u, v), measured depth d):
reprojection (π(K, T_i X_j) − (u, v)) / σ_px, and where d > 0, (z(T_i X_j) − d) / (σ_rel · d²)
-- a stereo sensor's depth error grows with the square of the distance. Frames: ``c2w`` OpenCV,
metres (scale SfM with :func:`capture_tools.sfm.metric_scale` first); camera 0 is held fixed (gauge).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from rsart.camera import Intrinsics

from .sfm import SfmResult, stable_depth


@dataclass
class BAReport:
    """Observations used, robust cost before/after, median reprojection (px) and depth residual (m) after."""

    observations: int
    depth_observations: int
    cost_before: float
    cost_after: float
    median_reproj_px: float
    median_depth_residual: float


def _tracks(sfm: SfmResult, names: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point ids from the observations' 3-D coordinates (shared points have identical xyz)."""
    cam_idx, pts_key, uv = [], [], []
    for i, n in enumerate(names):
        ob = sfm.observations.get(n)
        if ob is None or not len(ob):
            continue
        cam_idx.append(np.full(len(ob), i))
        pts_key.append(ob[:, 2:5])
        uv.append(ob[:, :2])
    keys = np.concatenate(pts_key)
    uniq, inv = np.unique(np.round(keys, 9), axis=0, return_inverse=True)
    return np.concatenate(cam_idx), inv.ravel(), np.concatenate(uv), uniq


def refine_rgbd(sfm: SfmResult, intrinsics: Intrinsics, depths: dict[str, np.ndarray], sigma_px: float = 1.0,
                sigma_rel: float = 0.006, max_nfev: int = 60) -> tuple[SfmResult, BAReport]:
    """Refined copy of ``sfm`` (metric) using ``depths`` (name -> (H, W) metres, 0 = none, colour-aligned)."""
    names = sorted(n for n in sfm.c2w if n in sfm.observations)
    cam, pid, uv, X0 = _tracks(sfm, names)
    H = W = None
    d_obs = np.zeros(len(cam))
    for i, n in enumerate(names):
        sel = cam == i
        d = depths.get(n)
        if d is None:
            continue
        d = stable_depth(d)
        H, W = d.shape
        u = np.clip(np.round(uv[sel, 0]).astype(int), 0, W - 1)
        v = np.clip(np.round(uv[sel, 1]).astype(int), 0, H - 1)
        d_obs[sel] = d[v, u]
    n_cam, n_pts = len(names), len(X0)
    w2c0 = [np.linalg.inv(sfm.c2w[n]) for n in names]
    x0 = np.concatenate([np.concatenate([Rotation.from_matrix(m[:3, :3]).as_rotvec(), m[:3, 3]]) for m in w2c0[1:]]
                        + [X0.ravel()])
    fixed = w2c0[0]
    has_d = d_obs > 0

    def unpack(x):
        poses = x[:6 * (n_cam - 1)].reshape(-1, 6)
        R = np.concatenate([fixed[None, :3, :3], Rotation.from_rotvec(poses[:, :3]).as_matrix()])
        t = np.concatenate([fixed[None, :3, 3], poses[:, 3:]])
        return R, t, x[6 * (n_cam - 1):].reshape(-1, 3)

    def residuals(x):
        R, t, X = unpack(x)
        pc = np.einsum("nij,nj->ni", R[cam], X[pid]) + t[cam]
        z = pc[:, 2]
        zs = np.where(np.abs(z) < 1e-9, 1e-9, z)
        proj, _ = intrinsics.project(np.stack([pc[:, 0], pc[:, 1], zs], 1))
        ru = (proj[:, 0] - uv[:, 0]) / sigma_px
        rv = (proj[:, 1] - uv[:, 1]) / sigma_px
        rd = np.where(has_d, (z - d_obs) / (sigma_rel * np.maximum(d_obs, 1e-3) ** 2), 0.0)
        return np.concatenate([ru, rv, rd])

    m = len(cam)
    A = lil_matrix((3 * m, len(x0)), dtype=np.int8)
    rows = np.arange(m)
    for k in range(3):
        r = rows + k * m
        for c in range(6):
            ok = cam > 0
            A[r[ok], 6 * (cam[ok] - 1) + c] = 1
        for c in range(3):
            A[r, 6 * (n_cam - 1) + 3 * pid + c] = 1
    r0 = residuals(x0)
    res = least_squares(residuals, x0, jac_sparsity=A, loss="soft_l1", f_scale=2.0, method="trf",
                        x_scale="jac", max_nfev=max_nfev)
    R, t, X = unpack(res.x)
    c2w = dict(sfm.c2w)
    for i, n in enumerate(names):
        w2c = np.eye(4)
        w2c[:3, :3], w2c[:3, 3] = R[i], t[i]
        c2w[n] = np.linalg.inv(w2c)
    obs = {}
    for i, n in enumerate(names):
        sel = cam == i
        obs[n] = np.concatenate([uv[sel], X[pid[sel]]], axis=1)
    r1 = res.fun
    reproj = np.hypot(r1[:m], r1[m:2 * m]) * sigma_px
    dres = r1[2 * m:][has_d] * sigma_rel * d_obs[has_d] ** 2
    out = SfmResult(c2w, obs, X, sfm.scale, float(np.mean(reproj)))
    return out, BAReport(m, int(has_d.sum()), float(0.5 * np.sum(r0 ** 2)), float(res.cost),
                         float(np.median(reproj)), float(np.median(np.abs(dres))) if has_d.any() else float("nan"))
