"""An articulated Gaussian model: canonical Gaussians owned by rigid bodies on a kinematic tree.

Bodies: 0 is the static base, 1..K are movable. ``parent[b]`` is body b's parent (``parent[0] = -1``,
``0 <= parent[b] < b``, so bodies are listed parents first). Every movable body b has one joint:

* type ``revolute`` (value = angle in radians about the axis, right-hand rule) or ``prismatic``
  (value = displacement in metres along the axis);
* ``axis`` (3,) a direction (stored unnormalised, normalised on use) and ``pivot`` (3,) a point on the
  axis (metres; unused by prismatic joints), both in the **canonical frame**;
* one value per training state, ``values[s, b - 1]``.

Canonical frame: the world frame (metres, the object's base frame) with every joint at value 0; the
canonical Gaussians live there. The joint motion of body b is ``J_b(v) x = R x + t`` with
``R = Rot(axis, v)``, ``t = pivot - R pivot`` (revolute) or ``R = I``, ``t = v axis`` (prismatic), and
its world pose in a state is ``T_b = T_parent(b) ∘ J_b`` (``T_0 = identity``): a child's joint is
written in the canonical frame and carried along by its parent, so a flap on a lid is a chain.

Ownership: logits (N, K+1). Soft posing (while fitting) blends the bodies' motions of each centre with
weights ``softmax(logits / temperature)``; hard posing (at the end) moves each Gaussian with its argmax
body. Colours, opacities and scales are shared by all states; only centres and rotations are posed.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import torch
from torch import nn

from pd2gs.gaussians import CanonicalGaussians

JOINT_TYPES = ("revolute", "prismatic")


class ModelError(ValueError):
    """An inconsistent articulated model (message names the field)."""


def skew(u: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 3, 3) cross-product matrices [u]_x."""
    x, y, z = u.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], -1).reshape(u.shape[:-1] + (3, 3))


def axis_angle_matrix(u: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rodrigues: unit axes (..., 3) and angles (...) in radians -> rotations (..., 3, 3)."""
    k = skew(u)
    eye = torch.eye(3, dtype=u.dtype).expand(k.shape)
    s, c = torch.sin(angle)[..., None, None], torch.cos(angle)[..., None, None]
    return eye + s * k + (1 - c) * (k @ k)


def axis_angle_quat(u: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Unit axes (..., 3) and angles (...) -> unit quaternions (..., 4) (w, x, y, z)."""
    h = 0.5 * angle
    return torch.cat([torch.cos(h)[..., None], torch.sin(h)[..., None] * u], -1)


def quat_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product of (..., 4) (w, x, y, z) quaternions (broadcasting)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


@dataclass
class BodyPoses:
    """World poses of the K+1 bodies in one state: ``R`` (K+1, 3, 3), ``t`` (K+1, 3) metres, ``q`` (K+1, 4)
    the rotations as unit quaternions (w, x, y, z); x_world = R[b] x_canonical + t[b]."""

    R: torch.Tensor
    t: torch.Tensor
    q: torch.Tensor


class ArticulatedGaussians(nn.Module):
    """Canonical Gaussians + ownership logits + a kinematic tree of joints with per-state values.

    Args:
        gaussians: the canonical Gaussians (N of them), canonical frame.
        parent: K+1 ints, ``parent[0] = -1``, ``0 <= parent[b] < b``.
        joint_types: K strings, ``revolute`` | ``prismatic``, for bodies 1..K.
        axes: (K, 3) joint directions (any non-zero norm), canonical frame.
        pivots: (K, 3) points on the axes (m), canonical frame.
        values: (S, K) joint values per training state (rad | m).
        ownership: (N,) int labels in [0, K] (turned into logits +/- ``confidence``) or (N, K+1) logits.
        temperature: softmax temperature of the soft ownership (annealed by the fit).
    """

    def __init__(self, gaussians: CanonicalGaussians, parent: Sequence[int], joint_types: Sequence[str],
                 axes, pivots, values, ownership, temperature: float = 1.0, confidence: float = 4.0):
        super().__init__()
        K = len(joint_types)
        parent = [int(p) for p in parent]
        if len(parent) != K + 1 or parent[0] != -1 or any(not 0 <= parent[b] < b for b in range(1, K + 1)):
            raise ModelError(f"parent: need K+1={K + 1} entries, parent[0] = -1 and 0 <= parent[b] < b; got {parent}")
        bad = [t for t in joint_types if t not in JOINT_TYPES]
        if bad:
            raise ModelError(f"joint_types: {bad[0]!r} is not one of {', '.join(JOINT_TYPES)}")
        dt = gaussians.means.dtype
        axes = torch.as_tensor(axes, dtype=dt).reshape(K, 3)
        if K and bool((axes.norm(dim=1) < 1e-9).any()):
            raise ModelError("axes: every joint axis needs a non-zero direction")
        values = torch.as_tensor(values, dtype=dt)
        if values.ndim != 2 or values.shape[1] != K:
            raise ModelError(f"values: expected (S, {K}), got {tuple(values.shape)}")
        self.gaussians = gaussians
        self.parent = parent
        self.joint_types = list(joint_types)
        self.axes = nn.Parameter(axes.clone())
        self.pivots = nn.Parameter(torch.as_tensor(pivots, dtype=dt).reshape(K, 3).clone())
        self.values = nn.Parameter(values.clone())
        self.ownership_logits = nn.Parameter(ownership_logits(ownership, gaussians.num, K, confidence, dt))
        self.temperature = float(temperature)
        self.hard = False

    # ------------------------------------------------------------------ sizes
    @property
    def num_bodies(self) -> int:
        """K + 1 (the base included)."""
        return len(self.parent)

    @property
    def num_states(self) -> int:
        return int(self.values.shape[0])

    @property
    def unit_axes(self) -> torch.Tensor:
        """(K, 3) unit joint axes, canonical frame."""
        return self.axes / self.axes.norm(dim=1, keepdim=True)

    # ------------------------------------------------------------------ ownership
    def weights(self) -> torch.Tensor:
        """(N, K+1) ownership weights: softmax(logits / temperature), or one-hot argmax when ``hard``."""
        if self.hard:
            return nn.functional.one_hot(self.labels(), self.num_bodies).to(self.ownership_logits.dtype)
        return torch.softmax(self.ownership_logits / self.temperature, dim=1)

    def labels(self) -> torch.Tensor:
        """(N,) hard owner of each Gaussian (argmax of the logits), 0 = base."""
        return self.ownership_logits.detach().argmax(dim=1)

    def harden(self) -> None:
        """Switch to hard ownership (each Gaussian moves with its argmax body only)."""
        self.hard = True

    # ------------------------------------------------------------------ kinematics
    def body_poses(self, state: int | None = None, values: torch.Tensor | None = None) -> BodyPoses:
        """World poses of every body in training ``state`` or for explicit joint ``values`` (K,)."""
        if values is None:
            if state is None or not -self.num_states <= state < self.num_states:
                raise ModelError(f"state: {state} is not a training state index (0..{self.num_states - 1})")
            values = self.values[state]
        dt = self.axes.dtype
        u = self.unit_axes
        Rs, ts, qs = [torch.eye(3, dtype=dt)], [torch.zeros(3, dtype=dt)], [torch.tensor([1.0, 0, 0, 0], dtype=dt)]
        for b in range(1, self.num_bodies):
            j, v = b - 1, values[b - 1]
            if self.joint_types[j] == "revolute":
                Rj = axis_angle_matrix(u[j], v)
                tj = self.pivots[j] - Rj @ self.pivots[j]
                qj = axis_angle_quat(u[j], v)
            else:
                Rj, tj = torch.eye(3, dtype=dt), v * u[j]
                qj = torch.tensor([1.0, 0, 0, 0], dtype=dt)
            p = self.parent[b]
            Rs.append(Rs[p] @ Rj)
            ts.append(Rs[p] @ tj + ts[p])
            qs.append(quat_mul(qs[p], qj))
        return BodyPoses(torch.stack(Rs), torch.stack(ts), torch.stack(qs))

    def pose(self, state: int | None = None, values: torch.Tensor | None = None, hard: bool | None = None
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """Posed Gaussians in one state -> (means (N, 3) m, quats (N, 4) (w, x, y, z)), world frame.

        Soft: ``mu = sum_b w_ib (R_b mu_i + t_b)`` and ``q = normalise(sum_b w_ib q_b) * q_i`` (body
        quaternions are blended in the hemisphere of the base's identity). Hard: the argmax body's motion.
        ``hard``: which of the two (None: the model's own ``hard`` flag).
        """
        bp = self.body_poses(state, values)
        g = self.gaussians
        if self.hard if hard is None else hard:
            lab = self.labels()
            means = (bp.R[lab] @ g.means[..., None])[..., 0] + bp.t[lab]
            qb = bp.q[lab]
        else:
            w = self.weights()
            moved = torch.einsum("bij,nj->nbi", bp.R, g.means) + bp.t[None]   # (N, K+1, 3)
            means = (w[..., None] * moved).sum(1)
            q = bp.q * torch.where(bp.q[:, :1] < 0, -1.0, 1.0).to(bp.q)
            qb = w @ q
            qb = qb / qb.norm(dim=1, keepdim=True).clamp_min(1e-12)
        quats = quat_mul(qb, g.quats / g.quats.norm(dim=1, keepdim=True))
        return means, quats

    def render(self, state: int, K: torch.Tensor, w2c: torch.Tensor, width: int, height: int,
               background: torch.Tensor | None = None, backend: str = "cpu", values: torch.Tensor | None = None):
        """Rasterize the model posed in ``state`` (or at ``values``) into one camera -> RenderOutput."""
        from pd2gs.render import rasterize

        means, quats = self.pose(state, values)
        g = self.gaussians
        dt = means.dtype
        return rasterize(means, quats, torch.exp(g.log_scales), g.colors, g.opacities, K.to(dt), w2c.to(dt),
                         width, height, background=None if background is None else background.to(dt),
                         backend=backend)

    def joint_dict(self, b: int) -> dict:
        """Body b's joint (b >= 1) as plain numbers: type, unit axis, pivot, parent, values per state."""
        j = b - 1
        return {"type": self.joint_types[j], "axis": self.unit_axes[j].detach().tolist(),
                "pivot": self.pivots[j].detach().tolist(), "parent": self.parent[b],
                "values": self.values[:, j].detach().tolist()}


def ownership_logits(ownership, n: int, K: int, confidence: float = 4.0, dtype=torch.float32) -> torch.Tensor:
    """(N,) labels in [0, K] -> (N, K+1) logits (+confidence/2 at the label, -confidence/2 elsewhere), or
    (N, K+1) logits passed through after a shape check."""
    own = torch.as_tensor(ownership)
    if own.ndim == 1:
        if own.shape[0] != n or (own.numel() and (int(own.min()) < 0 or int(own.max()) > K)):
            raise ModelError(f"ownership: expected {n} labels in [0, {K}], got shape {tuple(own.shape)}")
        logits = torch.full((n, K + 1), -confidence / 2, dtype=dtype)
        logits[torch.arange(n), own.long()] = confidence / 2
        return logits
    if tuple(own.shape) != (n, K + 1):
        raise ModelError(f"ownership: expected ({n}, {K + 1}) logits or ({n},) labels, got {tuple(own.shape)}")
    return own.to(dtype).clone()


def canonical_gaussians(means, quats, scales, colors, opacities, dtype=torch.float32) -> CanonicalGaussians:
    """CanonicalGaussians from activated values: means (N,3) m, quats (N,4), scales (N,3) std-devs (m),
    colors (N,3) in [0,1], opacities (N,) in (0,1)."""
    def t(x):
        return torch.as_tensor(x).to(dtype)
    g = CanonicalGaussians(t(means), torch.log(t(scales)), t(colors), 0.5, t(quats))
    op = t(opacities).clamp(1e-4, 1 - 1e-4)
    g.opacity_logits = nn.Parameter(torch.log(op / (1 - op)))
    if dtype != torch.float32:
        g.to(dtype)
    return g
