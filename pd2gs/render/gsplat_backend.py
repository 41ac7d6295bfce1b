"""The ``gsplat`` backend: gsplat's CUDA kernels (optional extra, needs a CUDA GPU and nvcc).

Built from gsplat's low-level calls (``fully_fused_projection``, ``isect_tiles``,
``isect_offset_encode``, ``rasterize_to_pixels``) rather than its ``rasterization`` wrapper, so
that the returned ``means2d`` is the very tensor the compositing step consumes:
``out.means2d.retain_grad()`` then yields the view-space gradient that densification reads
(a slice of ``rasterization``'s batched ``meta["means2d"]`` would get no gradient).

Conventions: the projection runs with pd2gs's own ``K`` (integer pixel centres), so ``means2d``
matches the other backends; gsplat's compositing samples pixel (x, y) at (x + 0.5, y + 0.5), so
the means are shifted by +0.5 px only for tile binning and compositing. Depth is carried as an
extra colour channel and normalised as in ``pd2gs.render._finish``. Per-label weights are
rendered as extra one-hot channels. gsplat computes in float32 on the GPU; outputs are returned
on the input device and dtype. Differences from the other backends, by design of gsplat's
kernels: alpha is clamped at 0.999 (not 0.99), tiles are binned with an opacity-aware extent,
and per-Gaussian max weights are not available.
"""
from __future__ import annotations

import math

import torch

from pd2gs.render.projection import LOW_PASS, NEAR_PLANE, TILE

_EXTENSION_PROBLEM: str | None = None  # "" once gsplat's CUDA extension loaded, else the reason


def gsplat_status() -> str | None:
    """None if the backend can run, otherwise the reason (a sentence naming the fix).

    Where gsplat and a CUDA GPU are present this loads gsplat's CUDA extension, which the first
    time JIT-compiles it (a few minutes; needs nvcc and ninja).
    """
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return ("backend 'gsplat' needs the optional gsplat package (pip install gsplat) and a "
                "CUDA GPU; use backend 'cpu' on this machine")
    if not torch.cuda.is_available():
        return "backend 'gsplat' needs a CUDA GPU and none is available; use backend 'cpu'"
    global _EXTENSION_PROBLEM
    if _EXTENSION_PROBLEM is None:  # probe once per process: a failed build is slow to repeat
        try:
            from gsplat.cuda._backend import _C
            _EXTENSION_PROBLEM = "" if _C is not None else (
                "gsplat's CUDA extension is unavailable (gsplat JIT-compiles it and needs the "
                "CUDA toolkit's nvcc and ninja); use backend 'cpu'")
        except Exception as e:  # a failed JIT build raises from inside torch's cpp_extension
            _EXTENSION_PROBLEM = (f"gsplat's CUDA extension failed to build or load "
                                  f"({type(e).__name__}: {e}); use backend 'cpu'")
    return _EXTENSION_PROBLEM or None


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
    from gsplat import fully_fused_projection, isect_offset_encode, isect_tiles, rasterize_to_pixels

    dev, f32 = torch.device("cuda"), torch.float32
    in_dev, dt = means.device, means.dtype

    def gpu(t):
        return t.to(dev, f32)

    opac = gpu(opacities)
    radii, m2d, depths, conics, _ = fully_fused_projection(
        gpu(means), None, gpu(quats), gpu(scales), gpu(w2c)[None], gpu(K)[None], width, height,
        eps2d=LOW_PASS, near_plane=NEAR_PLANE, packed=False, opacities=opac)
    # (N, 2) on the input device, in the graph between projection and compositing
    means2d = m2d[0].to(in_dev, dt)
    m2d_px = means2d.to(dev, f32)[None] + 0.5  # gsplat's pixel-centre convention
    tiles_x, tiles_y = math.ceil(width / TILE), math.ceil(height / TILE)
    _, isect_ids, flatten_ids = isect_tiles(m2d_px, radii, depths, TILE, tiles_x, tiles_y)
    offsets = isect_offset_encode(isect_ids, 1, tiles_x, tiles_y)

    feats = gpu(colors)
    if labels is not None:
        feats = torch.cat([feats, torch.nn.functional.one_hot(
            labels.long().to(dev), num_labels).to(f32)], dim=1)
    feats = torch.cat([feats, depths[0][:, None]], dim=1)  # last channel: sum_i w_i z_i
    bg = torch.zeros(1, feats.shape[1], device=dev, dtype=f32)
    if background is not None:
        bg[0, :3] = gpu(background)
    img, alpha = rasterize_to_pixels(m2d_px, conics, feats[None], opac[None], width, height, TILE,
                                     offsets, flatten_ids, backgrounds=bg)
    img, alpha = img[0], alpha[0, ..., 0]
    has = alpha > 1e-6
    depth = torch.where(has, img[..., -1] / torch.where(has, alpha, torch.ones_like(alpha)),
                        torch.zeros_like(alpha))
    lw = img[..., 3:3 + num_labels].detach().to(in_dev, dt) if labels is not None else None
    r = radii[0]
    if r.dim() == 2:  # gsplat >= 1.5: per-axis radii
        r = r.max(dim=-1).values
    return RenderOutput(img[..., :3].to(in_dev, dt), alpha.to(in_dev, dt), depth.to(in_dev, dt),
                        means2d, r.to(in_dev, torch.int32), lw, None)
