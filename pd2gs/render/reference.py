"""Reference rasterizer: pure PyTorch with autograd gradients (ground truth for tests).

Every tile evaluates all of its depth-sorted Gaussians for all of its 256 pixels at once, as a
padded (C, 256, K) batch of C tiles. The 3DGS compositing rules are applied literally:

    alpha = min(0.99, o * exp(-0.5 d^T conic d)), skipped when power > 0 or alpha < 1/255;
    the first Gaussian that would push transmittance below 1e-4 stops the pixel and is not
    composited (equivalent mask: keep_i = prod_{j<=i}(1 - alpha_j) >= 1e-4).

Tiles are grouped by list length ("bucketing") into chunks of about ``chunk_elems`` elements so
padding stays small; this is the only speed device, and it does not change the arithmetic.
"""
from __future__ import annotations

import torch

from pd2gs.render.projection import TILE, tile_grid

ALPHA_MAX = 0.99
ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4


def _chunks(counts: torch.Tensor, chunk_elems: int) -> list[torch.Tensor]:
    """Split tile ids (sorted by decreasing list length) into chunks of ~chunk_elems elements."""
    order = torch.argsort(counts, descending=True, stable=True)
    order = order[counts[order] > 0]
    chunks, start = [], 0
    while start < order.numel():
        kmax = int(counts[order[start]])
        n_tiles = max(1, chunk_elems // (TILE * TILE * max(kmax, 1)))
        chunks.append(order[start:start + n_tiles])
        start += n_tiles
    return chunks


def rasterize_reference(
    means2d: torch.Tensor,
    conics: torch.Tensor,
    opacities: torch.Tensor,
    features: torch.Tensor,
    offsets: torch.Tensor,
    gids: torch.Tensor,
    width: int,
    height: int,
    labels: torch.Tensor | None = None,
    num_labels: int = 0,
    want_max_weight: bool = False,
    chunk_elems: int = 1 << 20,
):
    """Composite binned screen-space Gaussians front to back.

    Args:
        means2d (N, 2), conics (N, 3), opacities (N,), features (N, F): per-Gaussian inputs.
        offsets (T + 1,), gids (P,): tile lists from ``pd2gs.render.binning``.
        labels (N,) int64 in [0, num_labels) or None: per-label weights are returned if given.
    Returns:
        feat (H, W, F) = sum_i w_i f_i (no background), trans (H, W) final transmittance,
        label_weights (H, W, L) or None, max_weight (N,) or None (max_x w_i(x), no grad).
    """
    tiles_x, tiles_y = tile_grid(width, height)
    n, nf = features.shape
    dt = features.dtype
    pad = lambda x: torch.cat([x, torch.zeros((1,) + x.shape[1:], dtype=x.dtype)])  # noqa: E731
    m2, con, op, ft = pad(means2d), pad(conics), pad(opacities), pad(features)
    counts = offsets[1:] - offsets[:-1]
    local = torch.arange(TILE * TILE)
    lx, ly = (local % TILE).to(dt), (local // TILE).to(dt)
    onehot = None
    if labels is not None:
        onehot = pad(torch.nn.functional.one_hot(labels.long(), num_labels).to(dt))
    maxw = torch.zeros(n + 1, dtype=dt) if want_max_weight else None

    n_tiles = tiles_x * tiles_y
    out_f = torch.zeros(n_tiles, TILE * TILE, nf, dtype=dt)
    out_t = torch.ones(n_tiles, TILE * TILE, dtype=dt)
    out_l = torch.zeros(n_tiles, TILE * TILE, num_labels, dtype=dt) if onehot is not None else None
    for tiles in _chunks(counts, chunk_elems):
        kmax = int(counts[tiles].max())
        j = torch.arange(kmax)
        pos = offsets[tiles][:, None] + j[None, :]
        valid_entry = j[None, :] < counts[tiles][:, None]
        ids = torch.where(valid_entry, gids[pos.clamp(max=gids.numel() - 1)], n)  # (C, K)
        px = ((tiles % tiles_x) * TILE).to(dt)[:, None] + lx[None, :]  # (C, 256)
        py = ((tiles // tiles_x) * TILE).to(dt)[:, None] + ly[None, :]
        dx = px[:, :, None] - m2[ids][:, None, :, 0]  # (C, 256, K)
        dy = py[:, :, None] - m2[ids][:, None, :, 1]
        ca, cb, cc = (con[ids][:, None, :, i] for i in range(3))
        power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
        alpha = torch.clamp(op[ids][:, None, :] * torch.exp(power), max=ALPHA_MAX)
        alpha = alpha * ((power <= 0) & (alpha >= ALPHA_MIN)).to(dt)
        keep = torch.cumprod(1 - alpha.detach(), dim=-1) >= T_MIN
        alpha = alpha * keep.to(dt)
        trans = torch.cumprod(1 - alpha, dim=-1)
        t_excl = torch.cat([torch.ones_like(trans[..., :1]), trans[..., :-1]], dim=-1)
        w = alpha * t_excl
        out_f = out_f.index_copy(0, tiles, w @ ft[ids])
        out_t = out_t.index_copy(0, tiles, trans[..., -1])
        if out_l is not None:
            out_l = out_l.index_copy(0, tiles, (w @ onehot[ids]).detach())
        if maxw is not None:
            inside = ((px < width) & (py < height)).to(dt)[:, :, None]  # tiles overhang the image
            wmax = (w.detach() * inside).amax(dim=1)
            maxw.scatter_reduce_(0, ids.reshape(-1), wmax.reshape(-1), "amax")

    def image(x: torch.Tensor) -> torch.Tensor:
        x = x.reshape(tiles_y, tiles_x, TILE, TILE, -1).permute(0, 2, 1, 3, 4)
        return x.reshape(tiles_y * TILE, tiles_x * TILE, -1)[:height, :width]

    feat = image(out_f)
    trans = image(out_t[..., None])[..., 0]
    lw = image(out_l) if out_l is not None else None
    return feat, trans, lw, (maxw[:n] if maxw is not None else None)
