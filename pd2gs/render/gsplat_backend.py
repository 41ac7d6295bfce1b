"""The ``gsplat`` backend: gsplat's CUDA rasterizer (optional extra, needs a CUDA GPU).

gsplat samples pixel (x, y) at (x + 0.5, y + 0.5) while pd2gs uses integer pixel centres, so the
principal point is shifted by +0.5 px before calling it. Per-Gaussian max weights are not
available from gsplat; per-label weights are rendered as extra one-hot colour channels.
"""
from __future__ import annotations

import torch


def gsplat_status() -> str | None:
    """None if the backend can run, otherwise the reason (a sentence naming the fix)."""
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return ("backend 'gsplat' needs the optional gsplat package (pip install gsplat) and a "
                "CUDA GPU; use backend 'cpu' on this machine")
    if not torch.cuda.is_available():
        return "backend 'gsplat' needs a CUDA GPU and none is available; use backend 'cpu'"
    return None


def rasterize_gsplat(means, quats, scales, colors, opacities, K, w2c, width, height,
                     background, labels, num_labels, return_max_weight):
    """Same contract as ``pd2gs.render.rasterize``; returns a RenderOutput on the input device."""
    from pd2gs.render import BackendUnavailable, RenderOutput

    reason = gsplat_status()
    if reason is not None:
        raise BackendUnavailable(reason)
    if return_max_weight:
        raise BackendUnavailable("backend 'gsplat' cannot return per-Gaussian max weights; "
                                 "use backend 'cpu' for visibility queries")
    from gsplat import rasterization

    dev = torch.device("cuda")
    k = K.to(dev, means.dtype).clone()
    k[0, 2] += 0.5
    k[1, 2] += 0.5
    feats = colors.to(dev)
    if labels is not None:
        onehot = torch.nn.functional.one_hot(labels.long().to(dev), num_labels).to(feats)
        feats = torch.cat([feats, onehot], dim=1)
    bg = None
    if background is not None:
        bg = torch.zeros(feats.shape[1] + 1, device=dev, dtype=feats.dtype)
        bg[:3] = background.to(dev, feats.dtype)
        bg = bg[None]
    img, alpha, meta = rasterization(
        means.to(dev), quats.to(dev), scales.to(dev), opacities.to(dev), feats,
        viewmats=w2c.to(dev, means.dtype)[None], Ks=k[None], width=width, height=height,
        near_plane=0.01, eps2d=0.3, render_mode="RGB+ED", backgrounds=bg, packed=False)
    img, alpha = img[0], alpha[0, ..., 0]
    lw = img[..., 3:3 + num_labels].detach() if labels is not None else None
    means2d = meta["means2d"][0]
    radii = meta["radii"][0]
    if radii.dim() == 2:
        radii = radii.max(dim=-1).values
    return RenderOutput(img[..., :3], alpha, img[..., -1], means2d, radii.int(), lw, None)
