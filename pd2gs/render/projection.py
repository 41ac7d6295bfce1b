"""EWA projection of 3D Gaussians to the image plane (pure PyTorch, autograd).

Shared by every backend, so the backends differ only in the 2D rasterization step.

Conventions
-----------
* Camera: OpenCV pinhole (x right, y down, z forward). ``K`` is the 3x3 intrinsic matrix in
  pixels with pixel centres at integer coordinates (pixel (x, y) is sampled at u = x, v = y),
  ``w2c`` the 4x4 world-to-camera transform. World units are metres.
* Quaternions are (w, x, y, z), need not be normalised (they are normalised here).
* ``scales`` are the per-axis standard deviations s > 0 (metres). The covariance uses the
  squared-scale convention of 3DGS: Sigma = R(q) diag(s)^2 R(q)^T.
* 2D covariances get the 3DGS low-pass dilation of 0.3 px^2 on the diagonal; the screen-space
  radius is ceil(3 * sqrt(lambda_max)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

TILE = 16
NEAR_PLANE = 0.01
LOW_PASS = 0.3


@dataclass
class Projected:
    """Screen-space Gaussians for one camera; N = number of input Gaussians.

    means2d: (N, 2) pixel coordinates (u, v), differentiable.
    conics: (N, 3) upper triangle (a, b, c) of the inverse 2D covariance, differentiable.
    depths: (N,) camera-space z in metres, differentiable.
    radii: (N,) int32 pixel radius; 0 marks a culled Gaussian (behind the near plane,
        degenerate or entirely off-screen).
    """

    means2d: torch.Tensor
    conics: torch.Tensor
    depths: torch.Tensor
    radii: torch.Tensor


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """(N, 4) quaternions (w, x, y, z), any norm -> (N, 3, 3) rotation matrices."""
    q = quats / quats.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]
    return torch.stack(rows, dim=-1).reshape(q.shape[:-1] + (3, 3))


def covariance3d(quats: torch.Tensor, scales: torch.Tensor) -> torch.Tensor:
    """(N, 4) quats and (N, 3) std-dev scales -> (N, 3, 3) Sigma = R diag(s)^2 R^T."""
    rs = quat_to_rotmat(quats) * scales[:, None, :]
    return rs @ rs.transpose(1, 2)


def project_gaussians(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    K: torch.Tensor,
    w2c: torch.Tensor,
    width: int,
    height: int,
    near: float = NEAR_PLANE,
) -> Projected:
    """Project (N, 3) means with (N, 4) quats and (N, 3) scales into a ``width`` x ``height``
    image seen by a camera with (3, 3) intrinsics ``K`` and (4, 4) world-to-camera ``w2c``.

    The Jacobian is evaluated at the view direction clamped to 1.3x the field of view, as in
    3DGS, which keeps far off-screen Gaussians from exploding.
    """
    K = K.to(means)
    w2c = w2c.to(means)
    rot, trans = w2c[:3, :3], w2c[:3, 3]
    p = means @ rot.T + trans
    z = p[:, 2]
    in_front = z > near
    zs = torch.where(in_front, z, torch.ones_like(z))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    u = fx * p[:, 0] / zs + cx
    v = fy * p[:, 1] / zs + cy

    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lim_x_pos, lim_x_neg = (width - cx) / fx + 0.3 * tan_x, cx / fx + 0.3 * tan_x
    lim_y_pos, lim_y_neg = (height - cy) / fy + 0.3 * tan_y, cy / fy + 0.3 * tan_y
    tx = torch.minimum(torch.maximum(p[:, 0] / zs, -lim_x_neg), lim_x_pos)
    ty = torch.minimum(torch.maximum(p[:, 1] / zs, -lim_y_neg), lim_y_pos)
    zero = torch.zeros_like(zs)
    jac = torch.stack(
        [fx / zs, zero, -fx * tx / zs, zero, fy / zs, -fy * ty / zs], dim=-1
    ).reshape(-1, 2, 3)
    cov_cam = rot @ covariance3d(quats, scales) @ rot.T
    cov2d = jac @ cov_cam @ jac.transpose(1, 2)
    a = cov2d[:, 0, 0] + LOW_PASS
    b = cov2d[:, 0, 1]
    c = cov2d[:, 1, 1] + LOW_PASS
    det = a * c - b * b
    ok = in_front & (det > 0)
    det_safe = torch.where(ok, det, torch.ones_like(det))
    conics = torch.stack([c / det_safe, -b / det_safe, a / det_safe], dim=-1)

    with torch.no_grad():
        mid = 0.5 * (a + c)
        lam = mid + torch.sqrt(torch.clamp(mid * mid - det, min=0.1))
        radii = torch.ceil(3.0 * torch.sqrt(lam)).to(torch.int32)
        on_screen = (u + radii > 0) & (u - radii < width) & (v + radii > 0) & (v - radii < height)
        radii = torch.where(ok & on_screen, radii, torch.zeros_like(radii))
    return Projected(torch.stack([u, v], dim=-1), conics, z, radii)


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """Number of 16x16 tiles along x and y."""
    return math.ceil(width / TILE), math.ceil(height / TILE)


def tile_rects(means2d: torch.Tensor, radii: torch.Tensor, width: int, height: int):
    """Tile rectangle [xmin, xmax) x [ymin, ymax) touched by each Gaussian (3DGS getRect).

    Returns four (N,) int64 tensors; culled Gaussians (radius 0) get an empty rectangle.
    """
    tiles_x, tiles_y = tile_grid(width, height)
    m = means2d.detach()
    r = radii.to(m.dtype)
    xmin = torch.clamp(torch.floor((m[:, 0] - r) / TILE), 0, tiles_x).long()
    ymin = torch.clamp(torch.floor((m[:, 1] - r) / TILE), 0, tiles_y).long()
    xmax = torch.clamp(torch.floor((m[:, 0] + r + TILE - 1) / TILE), 0, tiles_x).long()
    ymax = torch.clamp(torch.floor((m[:, 1] + r + TILE - 1) / TILE), 0, tiles_y).long()
    culled = radii <= 0
    xmax = torch.where(culled, xmin, xmax)
    return xmin, xmax, ymin, ymax
