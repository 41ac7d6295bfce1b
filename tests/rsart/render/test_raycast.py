"""Depth and masks by ray casting are exact: analytic box depth, back-projection onto the mesh, per-part hits."""
from __future__ import annotations

import numpy as np
import trimesh

from rsart.camera import Camera, Intrinsics, look_at
from rsart.render.raycast import NO_HIT, SCENE_LABEL, build_scene, pixel_rays


def _slab_depth(o, d, lo, hi):
    """Ray parameter of the first hit of o + t d with the box [lo, hi] (slab method, float64), or inf."""
    with np.errstate(divide="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    tn, tf = np.max(np.minimum(t1, t2)), np.min(np.maximum(t1, t2))
    return tn if tn <= tf and tn > 0 else np.inf


def test_pixel_rays_are_camera_rays(small_intrinsics):
    cam = Camera(small_intrinsics, look_at(np.array([1.0, -0.7, 0.9]), np.zeros(3)))
    _, d = cam.rays()
    assert np.allclose(pixel_rays(cam), d, atol=1e-6)


def test_depth_of_known_box_is_analytic():
    box = trimesh.creation.box(extents=(0.4, 0.3, 0.2))
    box.apply_translation((0.05, -0.02, 0.1))
    lo, hi = box.bounds
    K = Intrinsics(200, 150, 180.0, 170.0, 99.5, 74.5)
    cam = Camera(K, look_at(np.array([0.5, -0.35, 0.45]), np.array([0.0, 0.0, 0.1])))
    hits = build_scene([[box]]).cast(cam)
    R, t = cam.c2w[:3, :3], cam.c2w[:3, 3]
    rng = np.random.default_rng(1)
    checked = 0
    for v, u in zip(rng.integers(0, 150, 400), rng.integers(0, 200, 400)):
        d = R @ np.array([(u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0])  # camera z = 1: t is z-depth
        z = _slab_depth(t, d, lo, hi)
        if np.isinf(z):
            assert hits.depth[v, u] == 0 and hits.label[v, u] == NO_HIT
        else:
            assert abs(float(hits.depth[v, u]) - z) < 1e-5, (u, v)
            assert hits.label[v, u] == 0
            checked += 1
    assert checked > 50  # the box covers a good part of the image
    # the principal-point pixel of an axis-aligned view: depth = distance to the top face
    K2 = Intrinsics(101, 101, 100.0, 100.0, 50.0, 50.0)
    top = Camera(K2, look_at(np.array([0.05, -0.02, 1.5]), np.array([0.05, -0.02, 0.0]), up=np.array([0, 1.0, 0])))
    assert abs(float(build_scene([[box]]).cast(top).depth[50, 50]) - 1.3) < 1e-5


def test_backprojected_depth_lies_on_posed_mesh(cabinet, small_intrinsics):
    values = {"lid_hinge": 1.0, "drawer_slide": 0.2}
    meshes = cabinet.posed_meshes(values)
    scene = build_scene([[m] for m in meshes])
    cam = Camera(small_intrinsics, look_at(np.array([0.8, 0.5, 0.7]), np.array([0.0, 0.0, 0.2])))
    hits = scene.cast(cam)
    pts = cam.backproject(hits.depth.astype(np.float64))
    assert len(pts) > 1000
    whole = trimesh.util.concatenate(meshes)
    _, dist, _ = trimesh.proximity.closest_point(whole, pts[:: max(1, len(pts) // 3000)])
    assert dist.mean() < 1e-3 and dist.max() < 1e-4


def test_mask_is_the_part_the_ray_hits_first(cabinet, small_intrinsics):
    values = {"lid_hinge": 0.9, "drawer_slide": 0.25}
    meshes = cabinet.posed_meshes(values)
    floor = trimesh.creation.box(extents=(3, 3, 0.01))
    floor.apply_translation((0, 0, -0.006))
    scene = build_scene([[m] for m in meshes], [floor])
    cam = Camera(small_intrinsics, look_at(np.array([0.7, -0.4, 0.6]), np.array([0.0, 0.0, 0.15])))
    hits = scene.cast(cam)
    mask = hits.part_mask()
    o, d = cam.rays()
    rng = np.random.default_rng(0)
    idx = rng.choice(mask.size, 600, replace=False)
    vv, uu = np.unravel_index(idx, mask.shape)
    origins, dirs = o[vv, uu], d[vv, uu]
    labels = list(range(len(meshes))) + [SCENE_LABEL]
    t_hit = np.full((len(labels), len(idx)), np.inf)  # ray parameter of each mesh's first hit (trimesh, float64)
    for k, m in enumerate(meshes + [floor]):
        loc, ray_i, _ = m.ray.intersects_location(origins, dirs, multiple_hits=False)
        t_hit[k, ray_i] = np.einsum("ij,ij->i", loc - origins[ray_i], dirs[ray_i]) / np.einsum("ij,ij->i", dirs[ray_i], dirs[ray_i])
    order = np.sort(t_hit, axis=0)
    with np.errstate(invalid="ignore"):  # inf - inf where a ray misses everything
        clear = ~(order[1] - order[0] < 1e-5)  # skip rays grazing two parts at the same point (a hinge edge)
    first = np.argmin(t_hit, axis=0)
    owner = np.where(np.isfinite(order[0]), np.asarray(labels)[first], -1)
    expected = np.where(owner >= 0, owner + 1, 0)
    assert set(np.unique(expected)) >= {0, 1, 2, 3}  # every part and the floor were sampled
    assert clear.sum() > 0.98 * len(idx)
    assert np.array_equal(mask[vv, uu][clear], expected[clear])
    assert np.array_equal(hits.label[vv, uu] == SCENE_LABEL, owner == SCENE_LABEL)
