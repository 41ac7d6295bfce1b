"""Local rigidity prior on the deformation (ours, not in the paper; switch: ``TrainConfig.rigidity_weight``).

Photometric loss alone lets a CPU-length run explain a large part motion with half-moved Gaussians
and ghosts, so parts do not move rigidly and Kabsch joints suffer. This prior asks every Gaussian to
keep its distances to its k nearest canonical neighbours in every state (an isometry / as-rigid-as-
possible term, as in Dynamic 3D Gaussians). A robust (L1) penalty lets the few neighbour pairs that
straddle a part boundary separate.

Frames: canonical and deformed means are in the object frame (scene units).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass
class NeighbourGraph:
    """k-nearest-neighbour pairs of the canonical Gaussians.

    idx: (N, k) int64 neighbour indices; rest: (N, k) canonical distances; scale: mean rest distance
    (normalises the loss so its weight does not depend on the scene's units).
    """

    idx: torch.Tensor
    rest: torch.Tensor
    scale: float

    @property
    def n(self) -> int:
        return int(self.idx.shape[0])


def knn_graph(means: torch.Tensor, k: int = 8) -> NeighbourGraph:
    """Graph of the k nearest neighbours of every centre (means (N, 3), N > k)."""
    from scipy.spatial import cKDTree

    pts = means.detach().cpu().numpy().astype(np.float64)
    k = max(1, min(k, len(pts) - 1))
    dist, idx = cKDTree(pts).query(pts, k=k + 1)
    idx = torch.as_tensor(idx[:, 1:], dtype=torch.int64)
    rest = torch.as_tensor(dist[:, 1:], dtype=torch.float32)
    return NeighbourGraph(idx, rest, float(rest.mean()) or 1.0)


def isometry_loss(deformed: torch.Tensor, graph: NeighbourGraph) -> torch.Tensor:
    """Mean |‖μ_i^(k) − μ_j^(k)‖ − ‖μ_i − μ_j‖| / scale over the graph's pairs (deformed (N, 3))."""
    nb = deformed.index_select(0, graph.idx.reshape(-1)).view(*graph.idx.shape, 3)
    d = (deformed[:, None, :] - nb).norm(dim=-1)
    return (d - graph.rest).abs().mean() / graph.scale
