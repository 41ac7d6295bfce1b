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
                      max_dist: float = 0.01, stride: int = 1) -> tuple[dict[str, np.ndarray], float]:
    """Refined copy of ``c2w`` and the final median ICP inlier RMSE (metres) over the views."""
    names = [n for n in sorted(c2w) if n in depths]
    cur = dict(c2w)
    local = {n: _view_cloud(view_points(intrinsics, depths[n], None if masks is None else masks.get(n), np.eye(4),
                                        stride), voxel) for n in names}
    names = [n for n in names if len(local[n][0]) >= 100]
    reg_icp = o3d.pipelines.registration
    rmse: list[float] = []
    for _ in range(rounds):
        world = {n: (local[n][0] @ cur[n][:3, :3].T + cur[n][:3, 3], local[n][1] @ cur[n][:3, :3].T) for n in names}
        rmse = []
        new = dict(cur)
        for n in names:
            # leave-one-out target: the other views' points and normals (a view matched to a fusion holding
            # itself would find its own points and stay put)
            target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(
                np.concatenate([world[m][0] for m in names if m != n])))
            target.normals = o3d.utility.Vector3dVector(np.concatenate([world[m][1] for m in names if m != n]))
            src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(local[n][0]))
            reg = reg_icp.registration_icp(src, target, max_dist, cur[n],
                                           reg_icp.TransformationEstimationPointToPlane(),
                                           reg_icp.ICPConvergenceCriteria(max_iteration=30))
            if reg.fitness > 0.3:
                new[n] = np.asarray(reg.transformation)
                rmse.append(reg.inlier_rmse)
        cur = new
    return cur, float(np.median(rmse)) if rmse else float("nan")
