"""Pinhole maths lives in rsart/camera.py: Intrinsics.project/unproject/directions and the K-matrix
functions (numpy or torch). Held bit for bit against the formulas the callers wrote inline before."""
import numpy as np
import pytest

from rsart.camera import Camera, Intrinsics, look_at, pinhole_project, pinhole_unproject

INTR = Intrinsics(64, 48, 57.3, 61.9, 31.7, 22.4)


def _old_unproject(k, u, v, z):  # capture_tools/joint.py:static_masks, align.py before
    return np.stack([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z], 1)


def test_unproject_and_project_match_the_old_formulas_exactly():
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.2, 3.0, (INTR.height, INTR.width))
    depth[rng.random(depth.shape) < 0.3] = 0
    v, u = np.nonzero(depth > 0)
    z = depth[v, u]
    pts = INTR.unproject(u, v, z)
    assert np.array_equal(pts, _old_unproject(INTR, u, v, z))
    uv, zz = INTR.project(pts)
    old_u = INTR.fx * pts[:, 0] / pts[:, 2] + INTR.cx
    old_v = INTR.fy * pts[:, 1] / pts[:, 2] + INTR.cy
    assert np.array_equal(uv[:, 0], old_u) and np.array_equal(uv[:, 1], old_v) and np.array_equal(zz, z)
    assert np.allclose(uv, np.stack([u, v], 1), atol=1e-9)  # a round trip lands on the pixel centres


def test_directions_and_pixel_rays_match_the_old_grid():
    from rsart.render.raycast import pixel_rays

    u, v = np.meshgrid(np.arange(INTR.width, dtype=np.float64), np.arange(INTR.height, dtype=np.float64))
    old = np.stack([(u - INTR.cx) / INTR.fx, (v - INTR.cy) / INTR.fy, np.ones_like(u)], axis=-1)
    assert np.array_equal(INTR.directions(), old)
    cam = Camera(INTR, look_at(np.array([1.0, -2.0, 0.7]), np.zeros(3)))
    assert np.array_equal(pixel_rays(cam), old.astype(np.float32) @ cam.c2w[:3, :3].T.astype(np.float32))
    o, d = cam.rays()
    assert np.array_equal(d, old @ cam.c2w[:3, :3].T)


def test_torch_variant_equals_numpy_and_carries_gradients():
    torch = pytest.importorskip("torch")
    K = torch.tensor(INTR.K, dtype=torch.float32)
    pts = torch.tensor([[0.1, -0.2, 1.5], [0.3, 0.05, 0.8]], dtype=torch.float32, requires_grad=True)
    uv, z = pinhole_project(K, pts)
    ref_uv, ref_z = pinhole_project(INTR.K, pts.detach().double().numpy())
    assert np.allclose(uv.detach().numpy(), ref_uv, atol=1e-4) and np.allclose(z.detach().numpy(), ref_z)
    uv.sum().backward()
    assert pts.grad is not None and torch.all(torch.isfinite(pts.grad)) and pts.grad[:, 2].abs().min() > 0
    back = pinhole_unproject(K, uv.detach()[:, 0], uv.detach()[:, 1], z.detach())
    assert torch.allclose(back, pts.detach(), atol=1e-5)
