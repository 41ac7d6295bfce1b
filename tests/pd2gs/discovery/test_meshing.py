"""TSDF fusion of exact ray-cast depth of a known box, and Gaussian depth rendering of a known plane."""
import numpy as np
import pytest
import trimesh

from pd2gs.discovery.meshing import clean_mesh, render_depth, tsdf_fuse
from rsart.camera import Camera, Intrinsics, look_at
from rsart.render.raycast import build_scene


def _ring(n=12, size=(128, 96), target=(0.05, 0.0, 0.05), radius=0.8):
    intr = Intrinsics(size[0], size[1], 110.0, 110.0, (size[0] - 1) / 2, (size[1] - 1) / 2, None)
    cams = []
    for i in range(n):
        az = 2 * np.pi * i / n
        el = 0.5 if i % 2 else -0.4
        eye = np.array(target) + radius * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        cams.append(Camera(intr, look_at(eye, np.array(target))))
    return cams


def test_tsdf_of_a_box_is_within_a_few_mm():
    box = trimesh.creation.box(extents=[0.3, 0.2, 0.1])
    box.apply_translation([0.05, 0.0, 0.05])
    cams = _ring()
    scene = build_scene([[box]])
    depths = [scene.cast(c).depth for c in cams]
    mesh = clean_mesh(tsdf_fuse(depths, cams, voxel=0.005))
    assert len(mesh.faces) > 1000
    p = trimesh.sample.sample_surface(mesh, 4000, seed=0)[0]
    d_pred = np.abs(trimesh.proximity.signed_distance(box, p))
    q = trimesh.sample.sample_surface(box, 4000, seed=0)[0]
    d_true = np.abs(trimesh.proximity.signed_distance(mesh, q))
    assert d_pred.mean() < 0.002 and np.percentile(d_pred, 95) < 0.004, (d_pred.mean(), np.percentile(d_pred, 95))
    assert d_true.mean() < 0.002 and np.percentile(d_true, 95) < 0.004, (d_true.mean(), np.percentile(d_true, 95))
    assert np.allclose(mesh.bounds, box.bounds, atol=0.015)   # corners may overshoot by 2-3 voxels (measured 2)


def test_tsdf_without_depth_is_empty():
    cams = _ring(2)
    assert len(tsdf_fuse([np.zeros((96, 128))] * 2, cams, 0.01).faces) == 0


def test_rendered_gaussian_depth_of_a_plane():
    """A dense layer of flat Gaussians on the plane z = 0 seen from 1 m above: expected depth = 1 m."""
    g = np.linspace(-0.3, 0.3, 61)
    xx, yy = np.meshgrid(g, g)
    means = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], 1)
    n = len(means)
    quats = np.tile([1.0, 0, 0, 0], (n, 1))
    scales = np.tile([0.01, 0.01, 0.001], (n, 1))
    intr = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5, None)
    cam = Camera(intr, look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3), up=np.array([0.0, 1.0, 0.0])))
    depth, alpha = render_depth(means, quats, scales, np.full((n, 3), 0.5), np.full(n, 0.9), cam)
    centre = depth[12:36, 16:48]
    assert (alpha[12:36, 16:48] > 0.99).all()
    assert np.abs(centre - 1.0).max() < 1e-3


@pytest.mark.parametrize("case", ["one pixel", "nan", "inf", "negative"])
def test_degenerate_depth_gives_an_empty_mesh_not_an_error(case):
    """A part seen in a pixel or two (open3d aborts: "No block is touched"), or non-finite depth, once made
    a whole object fail (eyeglasses_rs-0001 in the suite run)."""
    cam = Camera(Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5, None), np.eye(4))
    d = np.zeros((48, 64))
    d[10, 10] = 1.0
    if case != "one pixel":
        d[10:20, 10:20] = {"nan": np.nan, "inf": np.inf, "negative": -1.0}[case]
    mesh = tsdf_fuse([d, d], [cam, cam], 0.01)
    assert len(mesh.faces) == 0
    plane = np.zeros((48, 64))
    plane[10:40, 10:50] = 1.0
    plane[20, 20] = np.nan if case == "nan" else plane[20, 20]
    assert len(tsdf_fuse([plane, plane], [cam, cam], 0.01).faces) > 1000  # a bad pixel costs one pixel
