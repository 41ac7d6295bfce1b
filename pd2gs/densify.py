"""3DGS adaptive density control on the canonical Gaussians.

Clone small / split large Gaussians whose mean view-space positional gradient (in NDC units,
as in 3DGS) exceeds a threshold, prune low-opacity and oversized ones, reset opacities. Adam
moments follow their Gaussians; new Gaussians start with zero moments.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from pd2gs.gaussians import PARAM_NAMES, CanonicalGaussians, inverse_sigmoid
from pd2gs.render.projection import quat_to_rotmat


@dataclass
class DensifyStats:
    """Running sums per canonical Gaussian: ||d loss / d means2d|| (NDC) and view counts."""

    grad_sum: torch.Tensor
    count: torch.Tensor

    @staticmethod
    def zeros(n: int) -> "DensifyStats":
        return DensifyStats(torch.zeros(n), torch.zeros(n))

    def add(self, means2d_grad: torch.Tensor, radii: torch.Tensor, width: int, height: int) -> None:
        """Accumulate one view's (N, 2) pixel-space gradient of the projected means."""
        g = means2d_grad * torch.tensor([0.5 * width, 0.5 * height])
        vis = radii > 0
        # dense masked adds (boolean-index scatter is ~10x slower on 20k Gaussians)
        self.grad_sum += torch.where(vis, g.norm(dim=-1), 0.0)
        self.count += vis


def _replace(opt: torch.optim.Optimizer, model: CanonicalGaussians, keep: torch.Tensor,
             new_rows: dict[str, torch.Tensor]) -> None:
    """Set every parameter to cat(old[keep], new_rows[name]) and carry Adam state along."""
    for name in PARAM_NAMES:
        old = getattr(model, name)
        new = nn.Parameter(torch.cat([old.detach()[keep], new_rows[name]]))
        n_new = new_rows[name].shape[0]
        for group in opt.param_groups:
            for i, p in enumerate(group["params"]):
                if p is old:
                    group["params"][i] = new
                    st = opt.state.pop(old, None)
                    if st:
                        for key in ("exp_avg", "exp_avg_sq"):
                            v = st[key]
                            st[key] = torch.cat([v[keep], torch.zeros((n_new,) + v.shape[1:])])
                        opt.state[new] = st
        setattr(model, name, new)


def densify_and_prune(model: CanonicalGaussians, opt: torch.optim.Optimizer, stats: DensifyStats,
                      grad_threshold: float, extent: float, percent_dense: float,
                      min_opacity: float, max_gaussians: int, generator: torch.Generator) -> dict:
    """One densification step; returns counts {cloned, split, pruned, total}."""
    with torch.no_grad():
        n = model.num
        grads = stats.grad_sum / stats.count.clamp(min=1)
        big = grads >= grad_threshold
        scales = model.log_scales.exp()
        large = scales.max(dim=1).values > percent_dense * extent
        clone = big & ~large
        split = big & large
        room = max(0, max_gaussians - n)
        # honour the cap: prefer the largest gradients
        if int(clone.sum()) + int(split.sum()) > room:
            order = torch.argsort(torch.where(big, grads, torch.full_like(grads, -1.0)), descending=True)
            allowed = torch.zeros(n, dtype=torch.bool)
            allowed[order[:room]] = True
            clone &= allowed
            split &= allowed
        rows = {name: getattr(model, name).detach() for name in PARAM_NAMES}
        new = {name: [rows[name][clone]] for name in PARAM_NAMES}
        if split.any():
            s = scales[split].repeat(2, 1)
            rot = quat_to_rotmat(rows["quats"][split]).repeat(2, 1, 1)
            offs = torch.randn(s.shape, generator=generator) * s
            new["means"].append((rot @ offs[:, :, None])[:, :, 0] + rows["means"][split].repeat(2, 1))
            new["log_scales"].append(torch.log(s / 1.6))
            for name in ("quats", "color_logits", "opacity_logits"):
                x = rows[name][split]
                new[name].append(x.repeat(2, *([1] * (x.dim() - 1))))
        new_rows = {k: torch.cat(v) for k, v in new.items()}
        opac = model.opacities
        prune = (opac < min_opacity) | (scales.max(dim=1).values > 0.5 * extent) | split
        _replace(opt, model, ~prune, new_rows)
        return {"cloned": int(clone.sum()), "split": int(split.sum()),
                "pruned": int(prune.sum()) - int(split.sum()), "total": model.num}


def reset_opacity(model: CanonicalGaussians, opt: torch.optim.Optimizer, value: float = 0.01) -> None:
    """Clamp opacities to at most ``value`` and zero their Adam moments (3DGS opacity reset)."""
    with torch.no_grad():
        cur = model.opacity_logits
        cur.copy_(torch.minimum(cur, inverse_sigmoid(torch.tensor(value))))
        st = opt.state.get(cur)
        if st:
            st["exp_avg"].zero_()
            st["exp_avg_sq"].zero_()
