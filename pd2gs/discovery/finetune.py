"""Local fine-tune after splitting (paper Sec. 3.4): only the new children's rotation and opacity move.

A child's rotation update is one quaternion r shared by every state and applied in the Gaussian's own
frame (q^(k) <- q^(k) (x) r), so it stays consistent with the rigid per-state deformation. Loss: L1
between rendered and captured RGB over the given views of every state (the photometric part of
L_total; the D-SSIM term is left out here). Renders with ``pd2gs.render.rasterize``.
"""
from __future__ import annotations

import numpy as np
import torch

from rsart.camera import Camera

from .field import StateField


def _quat_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product of (N, 4) (w, x, y, z) quaternions."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def finetune_children(fld: StateField, children: np.ndarray, views: list[list[tuple[Camera, np.ndarray]]],
                      iters: int = 200, lr: float = 0.01, seed: int = 0, backend: str = "cpu",
                      background: tuple[float, float, float] | None = None) -> dict:
    """Optimise children's rotations and opacities in place; views[k] = [(camera, rgb uint8 (H,W,3))] of state k.

    ``background``: RGB in [0, 1] composited behind the Gaussians (the trainer's; None = black).

    -> {"loss_first", "loss_last"} (mean L1 over the first / last 10 iterations).
    """
    from pd2gs.render import rasterize

    if len(children) == 0 or iters <= 0 or not any(views):
        return {"loss_first": None, "loss_last": None}
    rng = np.random.default_rng(seed)
    ch = torch.as_tensor(children, dtype=torch.long)
    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    r = torch.zeros(len(children), 4)
    r[:, 0] = 1.0
    r.requires_grad_(True)
    op0 = np.clip(fld.opacities[children], 1e-4, 1 - 1e-4)
    logit = torch.tensor(np.log(op0 / (1 - op0)), dtype=torch.float32, requires_grad=True)
    optim = torch.optim.Adam([r, logit], lr=lr)
    bg = None if background is None else torch.tensor(background, dtype=torch.float32)
    pairs = [(k, i) for k in range(len(views)) for i in range(len(views[k]))]
    losses = []
    for _ in range(iters):
        k, i = pairs[int(rng.integers(len(pairs)))]
        cam, rgb = views[k][i]
        q = f32(fld.quats[k]).clone()
        q = q.index_put((ch,), _quat_mul(q[ch], r / r.norm(dim=-1, keepdim=True)))
        o = f32(fld.opacities).clone().index_put((ch,), torch.sigmoid(logit))
        out = rasterize(f32(fld.means[k]), q, f32(fld.scales[k]), f32(fld.colors), o, f32(cam.K), f32(cam.w2c),
                        cam.width, cam.height, background=bg, backend=backend)
        loss = (out.rgb - f32(rgb) / 255.0).abs().mean()
        optim.zero_grad()
        loss.backward()
        optim.step()
        losses.append(float(loss.detach()))
    with torch.no_grad():
        rn = (r / r.norm(dim=-1, keepdim=True))
        for k in range(fld.k):
            q = f32(fld.quats[k][children])
            fld.quats[k][children] = _quat_mul(q, rn).numpy()
        fld.opacities[children] = torch.sigmoid(logit).numpy()
    return {"loss_first": float(np.mean(losses[:10])), "loss_last": float(np.mean(losses[-10:]))}
