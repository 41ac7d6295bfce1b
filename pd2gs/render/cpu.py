"""The ``cpu`` backend: Numba kernels wrapped in one autograd node."""
from __future__ import annotations

import numba
import numpy as np
import torch

from pd2gs.render import cpu_kernels as kern
from pd2gs.render.projection import tile_grid, tile_rects
from pd2gs.render.reference import ALPHA_MAX, ALPHA_MIN, T_MIN


def bin_gaussians_cpu(
    means2d: torch.Tensor, depths: torch.Tensor, radii: torch.Tensor, width: int, height: int,
    conics: torch.Tensor | None = None, opacities: torch.Tensor | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Tile lists as ``binning.bin_gaussians_torch`` (offsets (T+1,), gids (P,)), as numpy.

    With ``conics`` and ``opacities`` the 3DGS tile rectangles are first shrunk to the tiles
    where alpha >= 1/255 is reachable, which drops only pairs that cannot contribute."""
    tiles_x, tiles_y = tile_grid(width, height)
    rect = [r.numpy().copy() for r in tile_rects(means2d, radii, width, height)]
    if conics is not None and opacities is not None:
        kern.tighten_rects(*rect, means2d.detach().contiguous().numpy(),
                           conics.detach().contiguous().numpy(),
                           opacities.detach().contiguous().numpy(), ALPHA_MIN)
    vis = torch.nonzero(radii > 0).flatten()
    order = vis[torch.argsort(depths.detach()[vis], stable=True)].numpy()
    xmin, xmax, ymin, ymax = rect
    return kern.bin_tiles(xmin, xmax, ymin, ymax, order, tiles_x, tiles_x * tiles_y)


class _CpuComposite(torch.autograd.Function):
    """(means2d, conics, opacities, features) -> (feat (H,W,4), trans (H,W), label weights,
    per-Gaussian max weight). Only the first two outputs are differentiable."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, features, offsets, gids, width, height,
                labels, num_labels, want_max):
        dt = means2d.detach().numpy().dtype
        n_in = means2d.shape[0]
        arrays = [x.detach().contiguous().numpy() for x in (means2d, conics, opacities, features)]
        consts = kern.make_consts(dt, ALPHA_MAX, ALPHA_MIN, T_MIN)
        tiles_x, _ = tile_grid(width, height)
        if labels is not None:
            lab = labels.detach().long().contiguous().numpy()
            lw = np.zeros((height, width, num_labels), dt)
        else:
            lab, lw = np.zeros(1, np.int64), np.zeros((1, 1, 0), dt)
        maxw_pair = np.zeros(gids.shape[0] if want_max else 0, dt)
        order = kern.tile_order(offsets, numba.get_num_threads())
        prep = kern.prep_gaussians(*arrays, ALPHA_MIN)
        out, trans, last = kern.forward_kernel(offsets, gids, prep, width, height,
                                               tiles_x, consts, lab, lw, maxw_pair, order)
        ctx.state = (offsets, gids, prep, n_in, width, height, tiles_x, consts, trans, last, order)
        n = means2d.shape[0]
        maxw = torch.from_numpy(kern.reduce_max(gids, maxw_pair, n)) if want_max else None
        lw_t = torch.from_numpy(lw) if labels is not None else None
        for extra in (lw_t, maxw):
            if extra is not None:
                ctx.mark_non_differentiable(extra)
        return torch.from_numpy(out), torch.from_numpy(trans), lw_t, maxw

    @staticmethod
    def backward(ctx, g_feat, g_trans, _g_lw, _g_max):
        offsets, gids, prep, n_in, width, height, tiles_x, consts, trans, last, order = ctx.state
        tdt = torch.from_numpy(prep[:0]).dtype
        gf = (g_feat if g_feat is not None else torch.zeros(height, width, 4)).to(tdt).contiguous().numpy()
        gt = (g_trans if g_trans is not None else torch.zeros(height, width)).to(tdt).contiguous().numpy()
        pair = kern.backward_kernel(offsets, gids, prep, width, height, tiles_x,
                                    consts, trans, last, gf, gt, order)
        g = torch.from_numpy(kern.reduce_pairs(gids, pair, n_in))
        return g[:, 0:2], g[:, 2:5], g[:, 5], g[:, 6:10], None, None, None, None, None, None, None


def rasterize_cpu(means2d, conics, opacities, features, offsets, gids, width, height,
                  labels=None, num_labels=0, want_max_weight=False):
    """Same contract as ``reference.rasterize_reference`` (features must have F = 4)."""
    if features.shape[1] != 4:
        raise ValueError(f"cpu backend composites exactly 4 channels (rgb + depth), got {features.shape[1]}")
    return _CpuComposite.apply(means2d, conics, opacities, features, offsets, gids, width,
                               height, labels, num_labels, want_max_weight)
