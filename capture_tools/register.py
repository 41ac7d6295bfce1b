"""Pedestal plane and twin registration: place the twin in the capture frame.

* :func:`pedestal_plane` -- RANSAC plane (open3d ``segment_plane``) through the non-object depth
  points just below the object: the pedestal top, whose normal is the capture's up direction.
* :func:`register_twin` -- the twin at the state's joint values, sampled on its surface, registered
  to the fused object depth: coarse global registration (FPFH features + RANSAC, open3d), then
  point-to-plane ICP; the residual is the ICP inlier RMSE and the fitness (fraction of capture points
  within the ICP distance of the twin).

Frames: all points in the capture frame (metric SfM frame); the returned ``T`` maps twin/world
(object base frame) points into the capture frame, so a camera's object-frame pose is T⁻¹ · c2w.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh

from rsart.errors import RsartError


def pedestal_plane(points: np.ndarray, object_points: np.ndarray, dist: float = 0.004, iters: int = 2000,
                   seed: int = 0) -> tuple[np.ndarray, int]:
    """((4,) plane n·x + d = 0 with n pointing towards the object, inlier count) from (N, 3) background points.

    Only background points within the object's horizontal reach are used (the pedestal top under it);
    the booth floor and curtain are further away.
    """
    if len(points) < 50:
        raise RsartError(f"pedestal plane: only {len(points)} background depth points")
    c = object_points.mean(0)
    r = np.percentile(np.linalg.norm(object_points - c, axis=1), 95)
    near = points[np.linalg.norm(points - c, axis=1) < 2.0 * r]
    if len(near) < 50:
        near = points
    o3d.utility.random.seed(seed)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(near))
    model, inl = pc.segment_plane(distance_threshold=dist, ransac_n=3, num_iterations=iters)
    plane = np.asarray(model, float)
    plane /= np.linalg.norm(plane[:3])
    if plane[:3] @ c + plane[3] < 0:
        plane = -plane
    return plane, len(inl)


def up_alignment(plane: np.ndarray) -> np.ndarray:
    """(4, 4) rigid transform taking the plane normal to +z and the plane to z = 0 (rotation about the
    origin's projection)."""
    n = plane[:3] / np.linalg.norm(plane[:3])
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(n, z)
    s, c = np.linalg.norm(v), float(n @ z)
    if s < 1e-12:
        R = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        R = np.eye(3) + vx + vx @ vx * ((1 - c) / s ** 2)
    T = np.eye(4)
    T[:3, :3] = R
    T[2, 3] = plane[3]  # a point x on the plane has n·x = -d -> (R x)_z = -d
    return T


@dataclass
class Registration:
    """``T`` (4, 4) twin/world -> capture frame; ICP ``rmse`` (m) and ``fitness``; coarse RANSAC fitness."""

    T: np.ndarray
    rmse: float
    fitness: float
    coarse_fitness: float

    def to_dict(self) -> dict:
        return {"T_world_to_capture": self.T.tolist(), "icp_rmse": self.rmse, "icp_fitness": self.fitness,
                "coarse_fitness": self.coarse_fitness}


def _fpfh(pc: o3d.geometry.PointCloud, voxel: float):
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    return o3d.pipelines.registration.compute_fpfh_feature(
        pc, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))


def register_twin(mesh: trimesh.Trimesh, capture_points: np.ndarray, voxel: float | None = None,
                  up_T: np.ndarray | None = None, seed: int = 0, n_samples: int = 30000,
                  good_fitness: float = 0.8) -> Registration:
    """Register ``mesh`` (the posed twin, world frame) to (N, 3) ``capture_points`` (object depth, capture frame).

    ``voxel`` defaults to 1/40 of the twin's diagonal. ``up_T`` (from :func:`up_alignment`), when given, is
    used, when FPFH+RANSAC ends below ``good_fitness``, to try 8 yaw starts about the up axis, keeping the
    best ICP result.
    """
    reg = o3d.pipelines.registration
    diag = float(np.linalg.norm(mesh.extents))
    voxel = voxel or diag / 40
    pts, normals = outer_surface_samples(mesh, n_samples, seed)
    # the twin is the target (exact normals from its faces); the capture is the source: every measured point
    # is pulled onto the twin, and twin surfaces the camera never saw (the bottom on the pedestal) pull nothing
    model = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(pts)))
    model.normals = o3d.utility.Vector3dVector(normals)
    scan = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(capture_points))
    model_d, scan_d = model.voxel_down_sample(voxel), scan.voxel_down_sample(voxel)
    if len(scan_d.points) < 30:
        raise RsartError(f"twin registration: only {len(scan_d.points)} capture points after downsampling")
    f_model, f_scan = _fpfh(model_d, voxel), _fpfh(scan_d, voxel)
    o3d.utility.random.seed(seed)
    coarse = reg.registration_ransac_based_on_feature_matching(
        model_d, scan_d, f_model, f_scan, True, 1.5 * voxel, reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel)],
        reg.RANSACConvergenceCriteria(200000, 0.999))
    model_f = model.voxel_down_sample(voxel / 4)
    model_f.normals = o3d.utility.Vector3dVector(np.asarray(model_f.normals) / np.linalg.norm(
        np.asarray(model_f.normals), axis=1, keepdims=True))
    scan_f = scan.voxel_down_sample(voxel / 3)

    def refine(T0: np.ndarray) -> np.ndarray:
        """ICP of the scan onto the twin, starting from T0 (twin -> capture); returns twin -> capture."""
        inv0 = np.linalg.inv(T0)
        r1 = reg.registration_icp(scan_d, model_f, 2 * voxel, inv0, reg.TransformationEstimationPointToPlane(),
                                  reg.ICPConvergenceCriteria(max_iteration=50))
        r2 = reg.registration_icp(scan_f, model_f, voxel / 2, r1.transformation,
                                  reg.TransformationEstimationPointToPlane(), reg.ICPConvergenceCriteria(max_iteration=50))
        return np.linalg.inv(np.asarray(r2.transformation))

    def fit(T: np.ndarray) -> float:  # fraction of capture points within voxel/2 of the placed twin
        return float(np.mean(capture_residuals(mesh, capture_points[::7], T) < voxel / 2))

    best = refine(np.asarray(coarse.transformation))
    best_fit = fit(best)
    if up_T is not None and best_fit < good_fitness:
        # FPFH+RANSAC did not land: with a known up direction the remaining unknowns are yaw and position,
        # so ICP is seeded from 8 yaws about the up axis and the best fit kept
        centre_c = capture_points.mean(0)
        centre_t = np.asarray(model.points).mean(0)
        inv_up = np.linalg.inv(up_T)
        for k in range(8):
            a = 2 * np.pi * k / 8
            Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
            T = np.eye(4)
            T[:3, :3] = inv_up[:3, :3] @ Rz
            T[:3, 3] = centre_c - T[:3, :3] @ centre_t
            r = refine(T)
            f = fit(r)
            if f > best_fit:
                best, best_fit = r, f
    return residual_of(mesh, capture_points, best, voxel, float(coarse.fitness))


def residual_of(mesh: trimesh.Trimesh, capture_points: np.ndarray, T: np.ndarray, voxel: float | None = None,
                coarse_fitness: float = float("nan")) -> Registration:
    """The :class:`Registration` of a given ``T`` (world -> capture): the RMS distance of the capture points
    to the placed twin over the inliers (< ``voxel``/2, default 1/80 of the twin diagonal) and their fraction.
    The honest direction: every measured point must lie on the twin."""
    voxel = voxel or float(np.linalg.norm(mesh.extents)) / 40
    d = capture_residuals(mesh, capture_points, T)
    inl = d < voxel / 2
    rmse = float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("inf")
    return Registration(np.asarray(T, float), rmse, float(inl.mean()), coarse_fitness)


def outer_surface_samples(mesh: trimesh.Trimesh, n: int, seed: int = 0, rays: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) points and normals on the *outer* surface of ``mesh`` (M <= n).

    A twin's whole mesh is its parts side by side, so it has inner faces (a lid's underside on the body's
    top) that no camera sees; ICP would pull the scan towards them. A sample is kept when at least one of
    ``rays`` directions in its normal's hemisphere escapes the mesh without a hit.
    """
    rng = np.random.default_rng(seed)
    pts, fidx = trimesh.sample.sample_surface(mesh, n, seed=seed)
    nrm = np.asarray(mesh.face_normals)[fidx]
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    eps = 1e-4 * float(np.linalg.norm(mesh.extents))
    keep = np.zeros(len(pts), bool)
    for k in range(rays):
        d = nrm if k == 0 else nrm + rng.normal(size=nrm.shape) * 0.7
        d = d * np.sign(np.sum(d * nrm, axis=1, keepdims=True))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        r = np.concatenate([pts + eps * nrm, d], axis=1).astype(np.float32)
        keep |= np.isinf(scene.cast_rays(o3d.core.Tensor(r))["t_hit"].numpy())
    return np.asarray(pts)[keep], nrm[keep]


def capture_residuals(mesh: trimesh.Trimesh, capture_points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(N,) distance (m) of each capture point to the twin surface placed by ``T`` (world -> capture)."""
    scene = o3d.t.geometry.RaycastingScene()
    m = mesh.copy()
    m.apply_transform(T)
    scene.add_triangles(o3d.core.Tensor(np.asarray(m.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(m.faces, np.uint32)))
    q = o3d.core.Tensor(np.asarray(capture_points, np.float32))
    return scene.compute_distance(q).numpy().astype(np.float64)
