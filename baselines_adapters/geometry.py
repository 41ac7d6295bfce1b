"""Frames and rigid-motion helpers shared by the adapters.

Frames: rsart's world is the object base frame, z up (docs/format.md). The methods train on the
exported cameras, so any consistent world frame works for them; the frame matters only to compare
with the peers' own data. Three method frames are offered:

* ``z-up`` (default): rsart's world unchanged.
* ``paris``: the peers' "rotated to z-up" ground-truth frame of PartNet-Mobility objects (PARIS
  ``preprocess.py``, reused by DTArt and ArtGS). For an object converted from PartNet-Mobility it is
  rsart's world turned +90° about z (``rsart.sources.partnet.PARIS_ZUP_TO_WORLD``, the one owner of
  that relation).
* ``y-up``: PartNet-Mobility's y-up annotation frame, i.e. the ``paris`` frame turned back by PARIS's
  ``R_coord`` (+90° about x).

Every exported pose, axis and mesh goes through the chosen frame and importers undo it.

Cameras: conversions between OpenCV and OpenGL/Blender camera axes go through
:class:`rsart.camera.Camera` (the one converter); this module only changes the *world* frame.
Units: metres (or the object's scene units) and radians.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.optimize import minimize_scalar
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from rsart.errors import RsartError
from rsart.kinematics import joint_motion, rotation_matrix

#: PARIS's ``R_coord``: PartNet's y-up annotation frame -> the peers' z-up GT frame (+90° about x).
Z_UP_FROM_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
Y_UP_FROM_Z_UP = Z_UP_FROM_Y_UP.T
FRAMES = ("z-up", "paris", "y-up")


def _paris_from_world() -> np.ndarray:
    from rsart.sources.partnet import PARIS_ZUP_TO_WORLD

    return PARIS_ZUP_TO_WORLD.T


@dataclass(frozen=True)
class MethodFrame:
    """The world frame a method's files use, as a rotation ``R`` (3, 3) from rsart's world into it."""

    name: str
    R: np.ndarray

    @staticmethod
    def named(name: str) -> "MethodFrame":
        if name == "z-up":
            return MethodFrame(name, np.eye(3))
        if name == "paris":
            return MethodFrame(name, _paris_from_world())
        if name == "y-up":
            return MethodFrame(name, Y_UP_FROM_Z_UP @ _paris_from_world())
        raise RsartError(f"unknown method frame {name!r} (choose from {', '.join(FRAMES)})")

    @property
    def T(self) -> np.ndarray:
        """(4, 4) rsart world -> method world."""
        out = np.eye(4)
        out[:3, :3] = self.R
        return out

    def points_to_method(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) or (3,) rsart-world points -> method frame."""
        return np.asarray(p, dtype=np.float64) @ self.R.T

    def points_from_method(self, p: np.ndarray) -> np.ndarray:
        return np.asarray(p, dtype=np.float64) @ self.R

    # directions transform like points (pure rotation)
    dirs_to_method = points_to_method
    dirs_from_method = points_from_method

    def pose_to_method(self, c2w: np.ndarray) -> np.ndarray:
        """(4, 4) camera-to-world in rsart's world -> camera-to-method-world (camera axes unchanged)."""
        return self.T @ np.asarray(c2w, dtype=np.float64)

    def pose_from_method(self, c2w: np.ndarray) -> np.ndarray:
        return self.T.T @ np.asarray(c2w, dtype=np.float64)

    def rigid_from_method(self, M: np.ndarray) -> np.ndarray:
        """A (4, 4) rigid motion written in the method frame, expressed in rsart's world."""
        return self.T.T @ np.asarray(M, dtype=np.float64) @ self.T

    def mesh_to_method(self, mesh: trimesh.Trimesh) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.points_to_method(mesh.vertices), np.asarray(mesh.faces), process=False)

    def mesh_from_method(self, mesh: trimesh.Trimesh) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.points_from_method(mesh.vertices), np.asarray(mesh.faces), process=False)


def unit(v: np.ndarray, what: str = "axis") -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n < 1e-12:
        raise RsartError(f"{what} {v.tolist()} has zero length or is not finite")
    return v / n


def rigid(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(4, 4) from a (3, 3) rotation and a (3,) translation."""
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = t
    return M


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """(4, 4) proper rigid motion minimising ||R src + t - dst|| over corresponding (N, 3) points (Kabsch).

    Hand-written (a dozen lines of SVD) because open3d's estimator needs point-cloud objects and gives
    no access to the reflection fix.
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    cs, cd = src.mean(0), dst.mean(0)
    H = (src - cs).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ S @ U.T
    return rigid(R, cd - R @ cs)


def pivot_from_motion(R: np.ndarray, t: np.ndarray, axis: np.ndarray, near: np.ndarray) -> np.ndarray:
    """A point on the rotation axis of x -> R x + t: the least-squares solution of (I - R) o = t (rank 2),
    moved along ``axis`` to the point closest to ``near`` (e.g. the part centroid).

    ``inv(I - R)`` (DTArt's formula) is singular for every rotation; lstsq is not.
    """
    o = np.linalg.lstsq(np.eye(3) - R, t, rcond=None)[0]
    return o + axis * float(np.dot(axis, np.asarray(near, np.float64) - o))


def motion_to_joint(M: np.ndarray, near: np.ndarray, min_rotation_deg: float) -> tuple[str, np.ndarray, np.ndarray, float]:
    """Read a start->end rigid motion (4, 4) of a part as a joint: (type, unit axis, origin, Δ rad | m).

    Revolute when the rotation angle is at least ``min_rotation_deg``, else prismatic along t.
    """
    R, t = M[:3, :3], M[:3, 3]
    rv = Rotation.from_matrix(R).as_rotvec()
    ang = float(np.linalg.norm(rv))
    if np.degrees(ang) >= min_rotation_deg:
        a = rv / ang
        return "revolute", a, pivot_from_motion(R, t, a, near), ang
    d = float(np.linalg.norm(t))
    if d < 1e-12:
        raise RsartError("the part does not move (identity motion): no joint can be read from it")
    return "prismatic", t / d, np.asarray(near, np.float64).copy(), d


def joint_to_motion(jtype: str, axis: np.ndarray, origin: np.ndarray, delta: float) -> np.ndarray:
    """(4, 4) start->end motion of a joint (rsart.kinematics.joint_motion)."""
    return joint_motion(jtype, unit(axis), np.asarray(origin, np.float64), float(delta))


def signed_delta(M: np.ndarray, jtype: str, axis: np.ndarray) -> float:
    """Amount of a rigid motion along a given joint axis: rotation angle about it (rad) or travel along it."""
    axis = unit(axis)
    if jtype == "revolute":
        return float(np.dot(Rotation.from_matrix(M[:3, :3]).as_rotvec(), axis))
    return float(np.dot(M[:3, 3], axis))


def same_topology(a: trimesh.Trimesh, b: trimesh.Trimesh) -> bool:
    """True when two meshes share their vertex count and faces (vertices then correspond)."""
    return len(a.vertices) == len(b.vertices) and a.faces.shape == b.faces.shape and np.array_equal(a.faces, b.faces)


@dataclass
class MotionFit:
    """The adapter's estimate of a part's start->end motion along a known joint axis."""

    delta: float          # rad (revolute) or scene units (prismatic)
    method: str           # "kabsch" | "axis-search"
    residual: float       # RMS (kabsch) or mean symmetric nearest-neighbour distance (search), scene units


def fit_motion_along_axis(start: trimesh.Trimesh, end: trimesh.Trimesh, jtype: str, axis: np.ndarray,
                          origin: np.ndarray, samples: int = 3000, seed: int = 0) -> MotionFit:
    """Estimate Δ of a 1-DoF joint (``axis``/``origin`` known) that moves mesh ``start`` onto mesh ``end``.

    Corresponding vertices (same topology): Kabsch, then the motion's component about/along the axis.
    Otherwise (independent reconstructions, e.g. two TSDF meshes): sample both surfaces, grid-search Δ
    minimising the symmetric mean nearest-neighbour distance (2° or 1/200 of the extent steps, on a
    600-point subsample), refine with a bounded scalar search on all samples. Units: radians / scene units.
    """
    axis = unit(axis)
    if same_topology(start, end):
        M = kabsch(start.vertices, end.vertices)
        moved = start.vertices @ M[:3, :3].T + M[:3, 3]
        res = float(np.sqrt(np.mean(np.sum((moved - end.vertices) ** 2, axis=1))))
        return MotionFit(signed_delta(M, jtype, axis), "kabsch", res)
    rng = np.random.default_rng(seed)
    ps_all, pe_all = _sample(start, samples, rng), _sample(end, samples, rng)
    ext = float(np.linalg.norm(np.ptp(np.vstack([ps_all, pe_all]), axis=0)))

    def make_cost(ps: np.ndarray, pe: np.ndarray):
        te = cKDTree(pe)

        def cost(d: float) -> float:
            M = joint_to_motion(jtype, axis, origin, d)
            q = ps @ M[:3, :3].T + M[:3, 3]
            # distances capped at the extent: far queries are slow in a k-d tree and carry no information
            a = np.minimum(te.query(q, distance_upper_bound=ext)[0], ext)
            b = np.minimum(cKDTree(q).query(pe, distance_upper_bound=ext)[0], ext)
            return float(a.mean() + b.mean())
        return cost

    coarse = make_cost(ps_all[:600], pe_all[:600])  # coarse grid on a subsample, refinement on all samples
    if jtype == "revolute":
        step = np.radians(2.0)
        grid = np.arange(-np.pi, np.pi + 1e-9, step)
    else:
        grid = np.linspace(-ext, ext, 201)
        step = grid[1] - grid[0]
    costs = [coarse(d) for d in grid]
    best = float(grid[int(np.argmin(costs))])
    fine = make_cost(ps_all, pe_all)
    r = minimize_scalar(fine, bounds=(best - 1.5 * step, best + 1.5 * step), method="bounded",
                        options={"xatol": 1e-7})
    d, res = float(r.x), float(r.fun)
    if jtype == "revolute":
        d = (d + np.pi) % (2 * np.pi) - np.pi
    return MotionFit(d, "axis-search", res)


def _sample(mesh: trimesh.Trimesh, n: int, rng: np.random.Generator) -> np.ndarray:
    if len(mesh.faces) == 0:
        if len(mesh.vertices) == 0:
            raise RsartError("empty mesh: cannot estimate a motion from it")
        return np.asarray(mesh.vertices, np.float64)
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=int(rng.integers(2 ** 31)))
    return np.asarray(pts, np.float64)


def remove_near(mesh: trimesh.Trimesh, others: list[trimesh.Trimesh], eps: float) -> trimesh.Trimesh:
    """``mesh`` without the faces whose three vertices all lie within ``eps`` of any mesh in ``others``.

    Used to split a single-joint run's static mesh (which still contains the other movable parts at the
    start state) into the base alone. Distances: open3d's exact unsigned point-to-mesh distance.
    """
    others = [o for o in others if o is not None and len(o.faces)]
    if not others or len(mesh.faces) == 0:
        return mesh
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for o in others:
        scene.add_triangles(o3d.core.Tensor(np.asarray(o.vertices, np.float32)),
                            o3d.core.Tensor(np.asarray(o.faces, np.uint32)))
    d = scene.compute_distance(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32))).numpy()
    near = d <= eps
    keep = ~near[mesh.faces].all(axis=1)
    out = trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)
    out.remove_unreferenced_vertices()
    return out


__all__ = ["MethodFrame", "FRAMES", "Z_UP_FROM_Y_UP", "Y_UP_FROM_Z_UP", "unit", "rigid", "kabsch",
           "pivot_from_motion", "motion_to_joint", "joint_to_motion", "signed_delta", "fit_motion_along_axis",
           "MotionFit", "remove_near", "rotation_matrix"]
