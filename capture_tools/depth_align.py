"""Dense depth refinement of camera poses: each view's object depth ICP-aligned to the others' fusion.

After SfM (+ RGB-D bundle adjustment) the remaining per-view errors are random slides/rotations
that a few hundred keypoints cannot pin down; the depth image has thousands of object pixels that
can. Each round fuses every view's masked depth with the current poses into one point cloud
(voxel-averaged, normals estimated), then moves each view by a point-to-plane ICP (open3d) of its
own points against that fusion. Frames: ``c2w`` OpenCV, metres.
"""
from __future__ import annotations

import numpy as np
import open3d as o3d

from rsart.camera import Camera, Intrinsics


def view_points(intrinsics: Intrinsics, depth: np.ndarray, mask: np.ndarray | None, c2w: np.ndarray,
                stride: int = 1) -> np.ndarray:
    """(M, 3) world points of the valid (and masked) depth pixels of one view (every ``stride``-th pixel)."""
    d = depth.copy()
    if mask is not None:
        d[~(mask > 0)] = 0
    if stride > 1:
        keep = np.zeros_like(d, dtype=bool)
        keep[::stride, ::stride] = True
        d[~keep] = 0
    return Camera(intrinsics, c2w).backproject(d)


def _view_cloud(points: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Voxel-downsampled (K, 3) points and their (K, 3) normals (oriented towards the camera at the origin)."""
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(voxel)
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * voxel, max_nn=30))
    pc.orient_normals_towards_camera_location(np.zeros(3))
    return np.asarray(pc.points), np.asarray(pc.normals)


def refine_with_depth(c2w: dict[str, np.ndarray], intrinsics: Intrinsics, depths: dict[str, np.ndarray],
                      masks: dict[str, np.ndarray] | None, voxel: float = 0.003, rounds: int = 2,
                      max_dist: float = 0.01, stride: int = 1, groups: dict[str, str] | None = None,
                      static: dict[str, np.ndarray] | None = None) -> tuple[dict[str, np.ndarray], float]:
    """Refined copy of ``c2w`` and the final median ICP inlier RMSE (metres) over the views.

    Joint mode (several states in one frame): ``groups`` (name -> state id) and ``static`` (name -> other
    state id -> (H, W) mask of the pixels static with respect to that state) make a view's target its own
    state's points plus only the *static* points of the other states (movable parts are elsewhere there).
    """
    names = [n for n in sorted(c2w) if n in depths]
    cur = dict(c2w)
    local = {n: _view_cloud(view_points(intrinsics, depths[n], None if masks is None else masks.get(n), np.eye(4),
                                        stride), voxel) for n in names}
    names = [n for n in names if len(local[n][0]) >= 100]
    cache: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}

    def usable(m: str, n: str) -> tuple[np.ndarray, np.ndarray]:
        """View m's local points and normals as a target for view n (only its static part across states)."""
        if groups is None or static is None or groups[m] == groups[n]:
            return local[m]
        key = (m, groups[n])
        if key not in cache:
            sm = static.get(m, {}).get(groups[n])
            pts = view_points(intrinsics, depths[m], sm, np.eye(4), stride) if sm is not None else np.zeros((0, 3))
            cache[key] = _view_cloud(pts, voxel) if len(pts) >= 10 else (np.zeros((0, 3)), np.zeros((0, 3)))
        return cache[key]

    reg_icp = o3d.pipelines.registration
    rmse: list[float] = []
    for _ in range(rounds):
        rmse = []
        new = dict(cur)
        for n in names:
            # leave-one-out target: the other views' points and normals (a view matched to a fusion holding
            # itself would find its own points and stay put)
            parts = [(usable(m, n), cur[m]) for m in names if m != n]
            target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(
                np.concatenate([p @ M[:3, :3].T + M[:3, 3] for (p, _), M in parts])))
            target.normals = o3d.utility.Vector3dVector(np.concatenate([q @ M[:3, :3].T for (_, q), M in parts]))
            src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(local[n][0]))
            reg = reg_icp.registration_icp(src, target, max_dist, cur[n],
                                           reg_icp.TransformationEstimationPointToPlane(),
                                           reg_icp.ICPConvergenceCriteria(max_iteration=30))
            if reg.fitness > 0.3:
                new[n] = np.asarray(reg.transformation)
                rmse.append(reg.inlier_rmse)
        cur = new
    return cur, float(np.median(rmse)) if rmse else float("nan")
