"""Joint SfM over every state of a capture: one reconstruction, one frame, one metric scale.

Between two states only the static base keeps its shape; features on a lid or drawer that moved would
tie the states together wrongly. The joint mode therefore lets *within-state* matches through as they
are and restricts *cross-state* matches to points measured on the static base:

1. each state is reconstructed on its own (:func:`capture_tools.pipeline.reconstruct_state`) and the twin
   registered to it, which places every state's capture frame relative to the first state's
   (twin_0 · twin_k⁻¹; measured 0.2° and 4 mm off on the simulated captures). An ICP of the states'
   fused depths onto each other was tried and made this worse (0.3°, 6 mm): the planes a moved part
   leaves behind (a closed lid's top 2 cm above the body top it uncovers) pull each other;
2. a pixel of a view of state k is *static with respect to state j* when its depth point, in the common
   frame, lies within ``tol`` of state j's fused object depth (:func:`static_masks`) -- a moved part
   finds nothing there, a base point finds itself. No twin part labels are used: on a real capture they
   come from the registration and are not more reliable than the depth itself;
3. one pycolmap SfM over all frames, in which a cross-state pair keeps only its verified inlier matches
   whose keypoints are static with respect to the other state in *both* images (a pair left with too
   few is dropped); metric scale from the depth of every frame, RGB-D bundle adjustment over all, and the
   leave-one-out depth ICP whose cross-state targets are only the other states' static points;
4. the twin registration of the state that fits best seeds one joint ICP of the twin, posed at every
   state's values, to every state's object depth at once (:func:`register_twin_joint`): all states share
   one world -> capture transform, as they share one camera frame.

If the joint model drops a state (fewer than 3 registered frames) or registers fewer frames than the
per-state models together, the per-state results are kept and the report says so.
"""
from __future__ import annotations

import numpy as np
import open3d as o3d
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from rsart.camera import Intrinsics
from rsart.errors import RsartError
from rsart.kinematics import Twin

from .depth_align import view_points
from .pipeline import (CaptureSettings, StateRecon, StateResult, estimate_poses, finish_state, pedestal_step,
                       place_state, registration_step)
from .register import Registration, outer_surface_samples


def fused_points(recon: StateRecon, intr: Intrinsics, stride: int = 2, voxel: float = 0.002) -> np.ndarray:
    """(N, 3) keyed object depth of every view of a state in its capture frame, voxel-downsampled."""
    pts = np.concatenate([view_points(intr, f.depth, recon.keyed[f.name], recon.c2w[recon.names[f.name]], stride)
                          for f in recon.frames])
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)).voxel_down_sample(voxel)
    return np.asarray(pc.points)


def static_masks(recons: list[StateRecon], ids: list[str], to_ref: list[np.ndarray], clouds: list[np.ndarray],
                 intr: Intrinsics, tol: float = 0.005) -> dict[str, dict[str, np.ndarray]]:
    """image name -> other state id -> (H, W) bool: the keyed pixels whose depth point (common frame) lies within
    ``tol`` (m) of that state's fused object depth."""
    trees = [cKDTree(c @ T[:3, :3].T + T[:3, 3]) for c, T in zip(clouds, to_ref)]
    out: dict[str, dict[str, np.ndarray]] = {}
    for k, rc in enumerate(recons):
        for f in rc.frames:
            name = rc.names[f.name]
            d = np.where(rc.keyed[f.name], f.depth, 0).astype(np.float64)
            v, u = np.nonzero(d > 0)
            M = to_ref[k] @ rc.c2w[name]
            z = d[v, u]
            cam = intr.unproject(u, v, z)
            pts = cam @ M[:3, :3].T + M[:3, 3]
            out[name] = {}
            for j, tree in enumerate(trees):
                if j == k:
                    continue
                near = tree.query(pts, distance_upper_bound=tol)[0] < tol
                m = np.zeros(d.shape, bool)
                m[v[near], u[near]] = True
                out[name][ids[j]] = m
    return out


def cross_state_filter(groups: dict[str, str], static: dict[str, dict[str, np.ndarray]]):
    """A :data:`capture_tools.sfm.PairFilter`: same-state pairs unchanged; a cross-state pair keeps the matches
    whose keypoints are static with respect to the other state in both images."""

    def lookup(mask: np.ndarray, xy: np.ndarray) -> np.ndarray:
        u = np.clip(np.round(xy[:, 0]).astype(int), 0, mask.shape[1] - 1)
        v = np.clip(np.round(xy[:, 1]).astype(int), 0, mask.shape[0] - 1)
        return mask[v, u]

    def keep(n1: str, n2: str, xy1: np.ndarray, xy2: np.ndarray, matches: np.ndarray):
        g1, g2 = groups.get(n1), groups.get(n2)
        if g1 == g2:
            return None
        return lookup(static[n1][g2], xy1[matches[:, 0]]) & lookup(static[n2][g1], xy2[matches[:, 1]])

    return keep


def register_twin_joint(meshes: list[trimesh.Trimesh], clouds: list[np.ndarray], T0: np.ndarray,
                        iters: int = 30, n_samples: int = 30000, seed: int = 0) -> np.ndarray:
    """One (4, 4) world -> capture transform fitting every state's twin (``meshes``, world frame, posed at the
    state's values) to its (N_k, 3) capture ``clouds`` at once: point-to-plane ICP from ``T0``, reach
    1/20 then 1/80 of the twin diagonal. Hand-written (a 6x6 normal equation) because open3d's ICP
    takes one cloud pair."""
    diag = float(np.linalg.norm(meshes[0].extents))
    models = []
    for m in meshes:
        p, n = outer_surface_samples(m, n_samples, seed)
        models.append((cKDTree(p), p, n))
    inv = np.linalg.inv(T0)  # capture -> world
    for it in range(iters):
        reach = diag / 20 if it < iters // 2 else diag / 80
        A, b = np.zeros((6, 6)), np.zeros(6)
        for (tree, p, n), c in zip(models, clouds):
            x = c @ inv[:3, :3].T + inv[:3, 3]
            dist, idx = tree.query(x, distance_upper_bound=reach)
            ok = np.isfinite(dist)
            x, s, nn = x[ok], p[idx[ok]], n[idx[ok]]
            r = np.sum((x - s) * nn, axis=1)
            J = np.concatenate([np.cross(x, nn), nn], axis=1)
            A += J.T @ J
            b += J.T @ r
        if not np.isfinite(A).all() or np.linalg.matrix_rank(A) < 6:
            break
        delta = -np.linalg.solve(A, b)
        step = np.eye(4)
        step[:3, :3] = Rotation.from_rotvec(delta[:3]).as_matrix()
        step[:3, 3] = delta[3:]
        inv = step @ inv
        if np.linalg.norm(delta) < 1e-7:
            break
    return np.linalg.inv(inv)


def process_joint(recons: list[StateRecon], ids: list[str], intr: Intrinsics, twin: Twin,
                  values: list[dict[str, float]], settings: CaptureSettings = CaptureSettings()
                  ) -> tuple[list[StateResult], dict]:
    """Steps 1-4 of the module docstring on per-state reconstructions (same camera ``intr``); returns the
    object-frame results per state and the joint figures (``{"used": False, "reason": ...}`` on fallback)."""
    recons = [renamed(rc, sid) for rc, sid in zip(recons, ids)]
    if len(recons) < 2:
        return [place_state(rc, intr, twin, v, settings) for rc, v in zip(recons, values)], \
            {"used": False, "reason": "one state"}
    peds = [pedestal_step(rc, intr) for rc in recons]
    regs = [registration_step(p, twin, v, settings) for p, v in zip(peds, values)]
    Ts = [r.T for r in regs]
    clouds = [fused_points(rc, intr) for rc in recons]
    to_ref = [Ts[0] @ np.linalg.inv(T) for T in Ts]
    static = static_masks(recons, ids, to_ref, clouds, intr)
    groups = {rc.names[f.name]: sid for rc, sid in zip(recons, ids) for f in rc.frames}
    images = {rc.names[f.name]: f.rgb for rc in recons for f in rc.frames}
    depths = {rc.names[f.name]: f.depth for rc in recons for f in rc.frames}
    keyed = {rc.names[f.name]: rc.keyed[f.name] for rc in recons for f in rc.frames}
    if len(images) != sum(len(rc.frames) for rc in recons):
        raise RsartError("joint SfM: state ids repeat")
    c2w, report = estimate_poses(images, intr, depths, keyed, settings, pair_filter=cross_state_filter(groups, static),
                                 groups=groups, static=static)
    per_reg = {sid: sum(rc.names[f.name] in c2w for f in rc.frames) for rc, sid in zip(recons, ids)}
    report.update(static_fraction={sid: float(np.mean([static[rc.names[f.name]][o].sum() / max(1, rc.keyed[f.name].sum())
                                                       for f in rc.frames for o in ids if o != sid]))
                                   for rc, sid in zip(recons, ids)}, registered_per_state=per_reg)
    if min(per_reg.values()) < 3 or sum(per_reg.values()) < sum(len(rc.frames) for rc in recons):
        report.update(used=False, reason="the joint model left frames out; per-state poses kept")
        return [finish_state(rc, intr, twin, v, p, r) for rc, v, p, r in zip(recons, values, peds, regs)], report
    joint = [StateRecon([f for f in rc.frames if rc.names[f.name] in c2w], rc.names, rc.keyed,
                        {n: M for n, M in c2w.items() if groups[n] == sid}, {**rc.report, "joint_sfm": True})
             for rc, sid in zip(recons, ids)]
    peds = [pedestal_step(rc, intr) for rc in joint]
    first = [registration_step(p, twin, v, settings) for p, v in zip(peds, values)]
    best = max(range(len(first)), key=lambda i: first[i].fitness)
    meshes = [twin.whole_mesh(v) for v in values]
    T = register_twin_joint(meshes, [p.object_points for p in peds], first[best].T, seed=settings.seed)
    report.update(used=True, registration_seed_state=ids[best])
    shared = Registration(T, 0.0, 0.0, first[best].coarse_fitness)  # residuals computed per state
    out = [finish_state(rc, intr, twin, v, p, registration_step(p, twin, v, settings, shared=shared))
           for rc, v, p in zip(joint, values, peds)]
    return out, report


def renamed(recon: StateRecon, state_id: str) -> StateRecon:
    """``recon`` with SfM image names prefixed by the state id (raw frame names repeat across recordings)."""
    names = {f.name: f"{state_id}__{recon.names[f.name]}" for f in recon.frames}
    c2w = {names[f.name]: recon.c2w[recon.names[f.name]] for f in recon.frames}
    return StateRecon(recon.frames, names, recon.keyed, c2w, recon.report)
