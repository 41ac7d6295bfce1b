"""Tile binning: which Gaussians touch which 16x16 tile, front to back.

Output format (shared by all tile-based backends):
    offsets: (T + 1,) int64, tile t owns list entries offsets[t]:offsets[t+1];
    gids: (P,) int64 Gaussian ids, sorted by tile and, inside a tile, by increasing depth
    (ties broken by Gaussian index). T = tiles_x * tiles_y, tiles numbered row-major.
"""
from __future__ import annotations

import torch

from pd2gs.render.projection import tile_grid, tile_rects


def bin_gaussians_torch(
    means2d: torch.Tensor, depths: torch.Tensor, radii: torch.Tensor, width: int, height: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Vectorised binning in PyTorch (no Python loop over Gaussians). Returns (offsets, gids)."""
    tiles_x, tiles_y = tile_grid(width, height)
    n = means2d.shape[0]
    xmin, xmax, ymin, ymax = tile_rects(means2d, radii, width, height)
    w = (xmax - xmin).clamp(min=0)
    counts = w * (ymax - ymin).clamp(min=0)
    gid = torch.repeat_interleave(torch.arange(n), counts)
    start = torch.cumsum(counts, 0) - counts
    local = torch.arange(gid.shape[0]) - start[gid]
    tx = xmin[gid] + local % w[gid].clamp(min=1)
    ty = ymin[gid] + local // w[gid].clamp(min=1)
    tile = ty * tiles_x + tx
    rank = torch.empty(n, dtype=torch.int64)
    rank[torch.argsort(depths.detach(), stable=True)] = torch.arange(n)
    order = torch.argsort(tile * max(n, 1) + rank[gid])
    gids = gid[order]
    per_tile = torch.bincount(tile, minlength=tiles_x * tiles_y)
    offsets = torch.zeros(tiles_x * tiles_y + 1, dtype=torch.int64)
    offsets[1:] = torch.cumsum(per_tile, 0)
    return offsets, gids
