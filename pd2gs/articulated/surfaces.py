"""The object's surface in each state, read off the stage-1 field's rendered depth, and a joint search on it.

Why (measured on refrigerator-0000's trained field, docs/pd2gs-parts.md): stage 1's Gaussian *centres* do
not follow a large rotation. Their Kabsch joints open the doors by 0.3–0.4 rad about hinges 0.8 m off,
against 1.68 and 1.82 rad, and a gradient fit started there stays there. That holds even with each
Gaussian given to its true part. The field's *rendered* depth still follows the doors: its points lie a
median 13–17 mm from the open doors and 50–62 mm from the closed ones. The projection score of
:mod:`.search` cannot tell the two apart on a white door in front of a white body (0.0506 at the true
joint against 0.0530 not moving). A distance to the rendered surface can: 0.36 against 0.43, and the
search below finds both hinges within 2.3°.

The depth comes from the RGB-trained field, never from a sensor: the method stays RGB-only.

**Surfaces.** For each state, the field's Gaussians in that state are rendered into up to ``per_state``
of its training cameras. Every pixel with alpha above ``alpha_min`` is back-projected at the rendered
expected depth. :class:`SurfaceViews` turns each state's points into a truncated distance grid
(``res`` voxels along the longest side of the padded box; distances over ``tau_rel`` x the box diagonal
count as 1). It has the :meth:`cost` interface of :class:`.search.ConsistencyViews`, so the hypotheses,
scoring and refinement of :func:`.search.search_body` run on it unchanged.

**Search.** :func:`search_surfaces` searches each movable body's joint against the *starting* model.
Bodies are searched independently and all set at the end. A body searched after another had moved
chose differently: measured on the refrigerator, the second door's hinge came out 19.5° off instead of
2.3°. The search leaves ownership alone; the gradient fit's own re-assignment takes care of it. Here
that did better than re-assigning by surface distance, which pulled 2854 Gaussians, half of them the
other door's, into the first door. Nothing is gated. The result is one start of the articulated
discovery among the others (``DiscoveryConfig.starts``). Its model is kept only if, after the fit and
model selection, it renders the held-out views better.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from pd2gs.data import Frame, backproject_frames

from .model import ArticulatedGaussians
from .ownership import view_subset
from .search import SearchConfig, _ramp, search_bodies


def field_surfaces(gaussians: list[dict], frames: list[Frame], per_state: int = 16, alpha_min: float = 0.5,
                   backend: str = "cpu") -> list[np.ndarray]:
    """Per state, the points (M_s, 3), world frame, metres, of the field's rendered surface.

    ``gaussians[s]``: state s's Gaussians (means (N, 3), quats (N, 4) wxyz, scales (N, 3) std-devs,
    colors (N, 3), opacities (N,)). ``frames``: views whose ``state`` indexes ``gaussians``. Up to
    ``per_state`` of each state's ``train`` views are used, spread evenly. A pixel counts where the
    rendered alpha exceeds ``alpha_min``; its point lies at the rendered expected depth along the
    pixel's ray (back-projected by :func:`pd2gs.data.backproject_frames`)."""
    from pd2gs.render import rasterize

    def t(x):
        return torch.as_tensor(np.asarray(x), dtype=torch.float32)

    out = []
    for s, g in enumerate(gaussians):
        own = [f for f in frames if f.state == s]
        args = [t(g[k]) for k in ("means", "quats", "scales", "colors")] + [t(g["opacities"]).reshape(-1)]
        rendered = []
        for i in view_subset(own, "train", per_state):
            f = own[i]
            with torch.no_grad():
                r = rasterize(*args, t(f.K), t(f.w2c), *f.size, backend=backend)
            depth = torch.where(r.alpha > alpha_min, r.depth, torch.zeros_like(r.depth))
            rendered.append(Frame(r.rgb, depth, t(f.K), t(f.w2c), s, "train", f.view_id))
        if not rendered:
            raise ValueError(f"frames: state {s} has no 'train' view to render its surface from")
        out.append(backproject_frames(rendered, max_points=10 ** 9)[0].double().numpy())
    return out


class SurfaceViews:
    """Per state a truncated distance grid to that state's surface points; :meth:`cost` scores posed points
    as :class:`.search.ConsistencyViews` does (0 on the surface, 1 at ``tau_rel`` x the box diagonal or
    beyond, and outside the grid)."""

    def __init__(self, clouds: list[np.ndarray], res: int = 128, tau_rel: float = 0.05):
        from scipy.ndimage import distance_transform_edt

        if not clouds or any(len(c) == 0 for c in clouds):
            raise ValueError("clouds: every state needs surface points")
        allp = np.concatenate(clouds)
        lo, hi = allp.min(0), allp.max(0)
        diag = float(np.linalg.norm(hi - lo)) or 1e-3
        self.lo = lo - 0.1 * diag
        self.voxel = float((hi - lo).max() + 0.2 * diag) / res
        self.shape = np.ceil((hi + 0.1 * diag - self.lo) / self.voxel).astype(int) + 1
        self.tau = tau_rel * diag
        self.grids = []
        for c in clouds:
            free = np.ones(self.shape, dtype=bool)
            i = np.clip(np.round((c - self.lo) / self.voxel).astype(int), 0, self.shape - 1)
            free[i[:, 0], i[:, 1], i[:, 2]] = False
            d = distance_transform_edt(free) * self.voxel
            self.grids.append(torch.from_numpy(np.minimum(d / self.tau, 1.0)).float()[None, None])

    def distance(self, s: int, X: torch.Tensor) -> torch.Tensor:
        """Points X (..., 3) world frame in state s -> (...) truncated distance / tau in [0, 1]."""
        u = (X.double() - torch.from_numpy(self.lo)) / self.voxel
        grid = (2 * u / torch.from_numpy(self.shape - 1.0) - 1).flip(-1).float()  # grid_sample: (x, y, z) = (W, H, D)
        inside = (grid.abs() <= 1).all(-1)
        v = F.grid_sample(self.grids[s], grid.reshape(1, -1, 1, 1, 3), mode="bilinear", padding_mode="border",
                          align_corners=True).reshape(X.shape[:-1])
        return torch.where(inside, v, torch.ones_like(v))

    def cost(self, X: torch.Tensor, colors: torch.Tensor | None = None) -> torch.Tensor:
        """Posed points X (H, S, M, 3) world frame -> (H, M): mean over states of the truncated distance."""
        return torch.stack([self.distance(s, X[:, s]) for s in range(X.shape[1])]).mean(0)


@dataclass
class SurfaceSearchResult:
    """Per body the chosen joint's type and its score before and after; ``seconds`` of the whole search."""

    chosen: dict[int, dict] = field(default_factory=dict)
    seconds: float = 0.0


@torch.no_grad()
def search_surfaces(model: ArticulatedGaussians, surfaces: SurfaceViews, ref: int = 0, cfg=None
                    ) -> SurfaceSearchResult:
    """Every movable body's joint chosen on ``surfaces`` (see the module doc), in place; ownership unchanged.
    ``cfg``: a :class:`.search.SearchConfig` (its hypothesis grid; ``min_explained`` is not applied)."""
    t0 = time.perf_counter()
    cfg = dataclasses.replace(cfg or SearchConfig(), min_explained=0.0)
    ramp = np.asarray(cfg.ramp, dtype=np.float64) if cfg.ramp is not None else _ramp(model.num_states, ref)
    res = SurfaceSearchResult(chosen=search_bodies(model, surfaces, ramp, cfg))
    res.seconds = time.perf_counter() - t0
    return res
