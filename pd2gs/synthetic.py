"""A small synthetic 2-part articulated scene rendered with the cpu rasterizer.

For tests and benchmarks when no captured RS-Art object is at hand: a box-shaped base and a lid
hinged on the base's back top edge (axis +x through (0, 0.2, 0.4)), opened by ``angles_deg`` in
the K states. Ground truth is a set of small opaque Gaussians on the two parts' surfaces; views
sit on a ring around the object looking at its centre.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from pd2gs.data import Frame
from pd2gs.render import rasterize


def _surface_points(lo, hi, n, g):
    """n points uniform on the surface of the box [lo, hi]."""
    lo, hi = torch.tensor(lo), torch.tensor(hi)
    p = lo + (hi - lo) * torch.rand(n, 3, generator=g)
    axis = torch.randint(0, 3, (n,), generator=g)
    side = torch.randint(0, 2, (n,), generator=g).bool()
    idx = torch.arange(n)
    p[idx, axis] = torch.where(side, hi[axis], lo[axis])
    return p


def scene_gaussians(n: int = 3000, seed: int = 0):
    """GT Gaussians (means, quats, scales, colors, opacities, part labels 0/1), rest pose."""
    g = torch.Generator().manual_seed(seed)
    nb = int(0.7 * n)
    base = _surface_points([-0.3, -0.2, 0.0], [0.3, 0.2, 0.38], nb, g)
    lid = _surface_points([-0.3, -0.2, 0.38], [0.3, 0.2, 0.42], n - nb, g)
    means = torch.cat([base, lid])
    labels = torch.cat([torch.zeros(nb, dtype=torch.long), torch.ones(n - nb, dtype=torch.long)])
    stripes = 0.5 + 0.5 * torch.sin(12 * means[:, 0:1] + 8 * means[:, 2:3])
    colors = torch.where(labels[:, None] == 0, torch.tensor([0.8, 0.3, 0.2]) * (0.6 + 0.4 * stripes),
                         torch.tensor([0.2, 0.4, 0.9]) * (0.6 + 0.4 * stripes))
    quats = torch.zeros(n, 4)
    quats[:, 0] = 1
    scales = torch.full((n, 3), 0.018)
    return means, quats, scales, colors, torch.full((n,), 0.9), labels


def open_lid(means: torch.Tensor, labels: torch.Tensor, angle_deg: float) -> torch.Tensor:
    """Rotate the lid (label 1) about the hinge (axis +x through (0, 0.2, 0.4)) by -angle."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    rot = torch.tensor([[1.0, 0, 0], [0, c, s], [0, -s, c]])
    pivot = torch.tensor([0.0, 0.2, 0.4])
    moved = (means - pivot) @ rot.T + pivot
    return torch.where(labels[:, None] == 1, moved, means)


def ring_cameras(n: int, width: int, height: int, radius: float = 1.6, elev_deg: float = 30.0):
    """n (K, w2c) OpenCV cameras on a ring looking at (0, 0, 0.2), z up, 45 degree vertical FOV."""
    f = 0.5 * height / math.tan(math.radians(22.5))
    K = torch.tensor([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    target = np.array([0.0, 0.0, 0.2])
    cams = []
    for i in range(n):
        az = 2 * math.pi * i / n + 0.3
        el = math.radians(elev_deg + 15 * math.sin(3 * az))
        eye = target + radius * np.array([math.cos(az) * math.cos(el), math.sin(az) * math.cos(el), math.sin(el)])
        z = target - eye
        z /= np.linalg.norm(z)
        x = np.cross(z, [0, 0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        c2w = np.eye(4)
        c2w[:3, :3] = np.stack([x, y, z], axis=1)
        c2w[:3, 3] = eye
        cams.append((K.clone(), torch.from_numpy(np.linalg.inv(c2w)).float()))
    return cams


@torch.no_grad()
def make_frames(angles_deg=(0.0, 20.0, 40.0, 60.0), views: int = 20, size=(64, 48),
                test_every: int = 5, n_gaussians: int = 3000, background=(1.0, 1.0, 1.0),
                seed: int = 0) -> list[Frame]:
    """Frames for every state (state index = position in ``angles_deg``)."""
    means, quats, scales, colors, opac, labels = scene_gaussians(n_gaussians, seed)
    bg = torch.tensor(background)
    frames = []
    for k, ang in enumerate(angles_deg):
        m = open_lid(means, labels, ang)
        for i, (K, w2c) in enumerate(ring_cameras(views, *size)):
            out = rasterize(m, quats, scales, colors, opac, K, w2c, *size, background=bg)
            split = "test" if i % test_every == test_every - 1 else "train"
            frames.append(Frame(out.rgb.clamp(0, 1).contiguous(), out.depth.contiguous(), K, w2c, k,
                                split, f"{i:03d}"))
    return frames
