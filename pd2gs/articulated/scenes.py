"""Small synthetic articulated scenes with known kinematic trees, for tests and measurements.

* ``lid``: :mod:`pd2gs.synthetic`'s box + lid (one revolute body, axis +x through (0, 0.2, 0.4), the
  lid opens by -angle about it, i.e. +angle about -x).
* ``flap``: the same lid carrying a flap hinged on its front edge (a chain: base -> lid -> flap).
* ``static``: the box and lid glued together (no movable body).
* ``twin``: the lid cut in two halves side by side (x < 0: body 1, x > 0: body 2) on the same hinge line,
  the second opening by ``twin_deg`` instead of ``angles_deg``: two coaxial hinges, so hanging one half on
  the other renders exactly as the flat tree does (woven baskets and double doors share a hinge line).
* ``tray``: the glued box holding a tray that is hidden inside it in the first state and slides out of its
  front face (-y) by ``tray_m`` metres (one prismatic body; the first state shows none of the tray).

Ground-truth centres are posed here with :func:`rsart.kinematics.joint_motion` (numpy), independently
of :class:`pd2gs.articulated.model.ArticulatedGaussians`, so tests can compare the two. Units metres and
radians; cameras OpenCV (see :func:`pd2gs.synthetic.ring_cameras`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from pd2gs.data import Frame
from pd2gs.render import rasterize
from pd2gs.synthetic import _surface_points, ring_cameras, scene_gaussians
from rsart.kinematics import joint_motion

SCENES = ("lid", "flap", "static", "tray", "twin")


@dataclass
class ArticulatedScene:
    """GT Gaussians (N) at rest (canonical frame) and a kinematic tree of K movable bodies over S states.

    means (N, 3) m; quats (N, 4) (w, x, y, z); scales (N, 3) std-devs m; colors (N, 3); opacities (N,);
    labels (N,) owner body 0..K; parent K+1 ints (parent[0] = -1); joint_types K strings; axes (K, 3) unit
    and pivots (K, 3) m in the canonical frame; values (S, K) rad | m.
    """

    means: torch.Tensor
    quats: torch.Tensor
    scales: torch.Tensor
    colors: torch.Tensor
    opacities: torch.Tensor
    labels: torch.Tensor
    parent: list[int]
    joint_types: list[str]
    axes: np.ndarray
    pivots: np.ndarray
    values: np.ndarray

    def body_transforms(self, state: int) -> list[np.ndarray]:
        """(4, 4) world transforms of bodies 0..K in ``state`` (parent transform @ own joint motion)."""
        T = [np.eye(4)]
        for b in range(1, len(self.parent)):
            j = b - 1
            T.append(T[self.parent[b]] @ joint_motion(self.joint_types[j], self.axes[j], self.pivots[j],
                                                      float(self.values[state, j])))
        return T

    def posed_means(self, state: int) -> torch.Tensor:
        """(N, 3) GT centres in ``state``."""
        T = np.stack(self.body_transforms(state))[self.labels.numpy()]
        m = self.means.double().numpy()
        return torch.from_numpy(np.einsum("nij,nj->ni", T[:, :3, :3], m) + T[:, :3, 3]).to(self.means.dtype)


def make_scene(name: str = "lid", n: int = 3000, angles_deg=(0.0, 20.0, 40.0, 60.0),
               flap_deg=(0.0, 30.0, 10.0, 50.0), seed: int = 0, tray_m=(0.0, 0.12, 0.24, 0.36),
               twin_deg=(0.0, 10.0, 30.0, 45.0)) -> ArticulatedScene:
    """One of :data:`SCENES` with ``len(angles_deg)`` states (lid opening angles; ``flap_deg`` the flap's
    angles relative to the lid, ``flap`` only; ``tray_m`` the tray's slide, ``tray`` only; ``twin_deg`` the
    second half lid's angles, ``twin`` only)."""
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; choose one of {', '.join(SCENES)}")
    means, quats, scales, colors, opac, labels = scene_gaussians(n, seed)
    lid_axis, lid_pivot = np.array([-1.0, 0, 0]), np.array([0.0, 0.2, 0.4])
    lid_vals = np.radians(np.asarray(angles_deg, dtype=np.float64))
    if name == "static":
        return ArticulatedScene(means, quats, scales, colors, opac, torch.zeros_like(labels), [-1], [],
                                np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((len(angles_deg), 0)))
    if name == "lid":
        return ArticulatedScene(means, quats, scales, colors, opac, labels, [-1, 0], ["revolute"],
                                lid_axis[None], lid_pivot[None], lid_vals[:, None])
    if name == "twin":
        labels = torch.where((labels == 1) & (means[:, 0] > 0), 2, labels)
        twin_vals = np.radians(np.asarray(twin_deg, dtype=np.float64))[: len(angles_deg)]
        return ArticulatedScene(means, quats, scales, colors, opac, labels, [-1, 0, 0], ["revolute"] * 2,
                                np.stack([lid_axis, lid_axis]), np.stack([lid_pivot, lid_pivot]),
                                np.stack([lid_vals, twin_vals], axis=1))
    if name == "tray":
        g = torch.Generator().manual_seed(seed + 2)
        nt = n // 4
        tray = _surface_points([-0.2, -0.17, 0.12], [0.2, 0.17, 0.26], nt, g)
        checks = 0.5 + 0.5 * torch.sign(torch.sin(25 * tray[:, 0:1]) * torch.sin(25 * tray[:, 1:2] + 9 * tray[:, 2:3]))
        cat = lambda a, b: torch.cat([a, b])  # noqa: E731
        return ArticulatedScene(cat(means, tray), cat(quats, quats[:nt]), cat(scales, scales[:nt]),
                                cat(colors, torch.tensor([0.95, 0.85, 0.2]) * (0.5 + 0.5 * checks)),
                                cat(opac, opac[:nt]), cat(torch.zeros_like(labels), torch.ones(nt, dtype=torch.long)),
                                [-1, 0], ["prismatic"], np.array([[0.0, -1.0, 0.0]]), np.array([[0.0, 0.0, 0.19]]),
                                np.asarray(tray_m, dtype=np.float64)[: len(angles_deg), None])
    g = torch.Generator().manual_seed(seed + 1)
    nf = n // 6
    flap = _surface_points([-0.25, -0.23, 0.24], [0.25, -0.21, 0.40], nf, g)
    stripes = 0.5 + 0.5 * torch.sin(10 * flap[:, 0:1] + 14 * flap[:, 2:3])
    means = torch.cat([means, flap])
    quats = torch.cat([quats, quats[:nf]])
    scales = torch.cat([scales, scales[:nf]])
    colors = torch.cat([colors, torch.tensor([0.2, 0.8, 0.3]) * (0.6 + 0.4 * stripes)])
    opac = torch.cat([opac, opac[:nf]])
    labels = torch.cat([labels, torch.full((nf,), 2, dtype=torch.long)])
    flap_vals = np.radians(np.asarray(flap_deg, dtype=np.float64)[: len(angles_deg)])
    return ArticulatedScene(means, quats, scales, colors, opac, labels, [-1, 0, 1], ["revolute", "revolute"],
                            np.stack([lid_axis, [1.0, 0, 0]]), np.stack([lid_pivot, [0.0, -0.22, 0.41]]),
                            np.stack([lid_vals, flap_vals], axis=1))


@torch.no_grad()
def render_scene(scene: ArticulatedScene, views: int = 12, size=(64, 48), test_every: int = 4,
                 background=(1.0, 1.0, 1.0)) -> tuple[list[Frame], list[torch.Tensor]]:
    """Frames of every state from a ring of ``views`` cameras, and per frame a silhouette mask (H, W)
    in {0, 1} (GT alpha > 0.5). Every ``test_every``-th view is split ``test``."""
    bg = torch.tensor(background)
    frames, masks = [], []
    for s in range(scene.values.shape[0]):
        m = scene.posed_means(s)
        for i, (K, w2c) in enumerate(ring_cameras(views, *size)):
            out = rasterize(m, scene.quats, scene.scales, scene.colors, scene.opacities, K, w2c, *size,
                            background=bg)
            split = "test" if i % test_every == test_every - 1 else "train"
            frames.append(Frame(out.rgb.clamp(0, 1).contiguous(), out.depth.contiguous(), K, w2c, s, split,
                                f"{i:03d}"))
            masks.append((out.alpha > 0.5).float())
    return frames, masks


def angle_between_deg(a, b) -> float:
    """Angle in degrees between two directions (sign-insensitive: an axis and its negation are equal)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = abs(float(a @ b)) / (np.linalg.norm(a) * np.linalg.norm(b))
    return math.degrees(math.acos(min(1.0, c)))


def line_distance(p, axis, q) -> float:
    """Distance (m) from point q to the line through p along ``axis``."""
    p, u, q = np.asarray(p, float), np.asarray(axis, float), np.asarray(q, float)
    u = u / np.linalg.norm(u)
    d = q - p
    return float(np.linalg.norm(d - u * (d @ u)))
