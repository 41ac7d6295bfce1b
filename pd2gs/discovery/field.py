"""The state-specific Gaussian fields discovery works on (K interaction states, N Gaussians).

PD²GS's deformation network turns the canonical field into one field per state; discovery only needs
those K fields (centres, rotations, scales per state; colour and opacity shared), plus, optionally, a
way to render an *interpolated* latent for the continuous-control pictures. :func:`as_state_field`
adapts a trained model exposing ``state_gaussians(state_id)`` to this record.

Conventions: world frame = object base frame (metres or scene units); quaternions (w, x, y, z);
``scales`` are per-axis standard deviations (the rasterizer's convention).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


@dataclass
class StateField:
    """K state-specific fields of N Gaussians sharing appearance.

    state_ids: K state ids, in the order of the first axis below.
    means: (K, N, 3) centres.  quats: (K, N, 4) (w, x, y, z).  scales: (K, N, 3) std-devs > 0.
    colors: (N, 3) RGB in [0, 1].  opacities: (N,) in [0, 1].
    labels: (N,) int part labels (0 = static) once discovered, else None.
    deform: optional ``f(state_a, state_b, t) -> (means (N,3), quats (N,4), scales (N,3))`` giving the
        field at the latent interpolated between two states' latents (t in [0, 1]).
    """

    state_ids: list[str]
    means: np.ndarray
    quats: np.ndarray
    scales: np.ndarray
    colors: np.ndarray
    opacities: np.ndarray
    labels: np.ndarray | None = None
    deform: Callable[[str, str, float], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        K, N = self.means.shape[:2]
        if len(self.state_ids) != K:
            raise ValueError(f"{len(self.state_ids)} state ids for {K} states")
        for name, arr, shape in (("quats", self.quats, (K, N, 4)), ("scales", self.scales, (K, N, 3)),
                                 ("colors", self.colors, (N, 3)), ("opacities", self.opacities, (N,))):
            if arr.shape != shape:
                raise ValueError(f"StateField.{name}: shape {arr.shape}, expected {shape}")

    @property
    def n(self) -> int:
        return int(self.means.shape[1])

    @property
    def k(self) -> int:
        return int(self.means.shape[0])

    def index(self, state_id: str) -> int:
        try:
            return self.state_ids.index(state_id)
        except ValueError:
            raise KeyError(f"state {state_id!r} is not in the field (states: {self.state_ids})") from None

    def subset_states(self, state_ids: list[str]) -> "StateField":
        """The same Gaussians restricted to ``state_ids`` (in that order)."""
        idx = [self.index(s) for s in state_ids]
        return StateField(list(state_ids), self.means[idx], self.quats[idx], self.scales[idx], self.colors,
                          self.opacities, self.labels, self.deform, dict(self.extra))

    def select(self, keep: np.ndarray) -> "StateField":
        """The Gaussians ``keep`` (bool (N,) or indices), all states."""
        return StateField(list(self.state_ids), self.means[:, keep], self.quats[:, keep], self.scales[:, keep],
                          self.colors[keep], self.opacities[keep],
                          None if self.labels is None else self.labels[keep], None, dict(self.extra))


def as_state_field(model: Any, state_ids: list[str]) -> StateField:
    """Adapt a trained PD²GS model to a :class:`StateField`.

    Accepts a StateField (returned as is, restricted to ``state_ids``) or any object with
    ``state_gaussians(state_id) -> dict`` of tensors/arrays ``means, quats, scales, colors,
    opacities`` and optionally ``interpolate(state_a, state_b, t) -> same dict`` (the field at the latent
    lerp(z_a, z_b, t)) and ``state_ids`` (the states it was trained on; :func:`discover` uses them).
    """
    if isinstance(model, StateField):
        return model.subset_states(state_ids)
    if not hasattr(model, "state_gaussians"):
        raise TypeError(f"{type(model).__name__} has no state_gaussians(state_id); cannot discover parts from it")
    per = [{k: _np(v) for k, v in model.state_gaussians(s).items()} for s in state_ids]
    deform = None
    if hasattr(model, "interpolate"):
        def deform(a: str, b: str, t: float):
            g = {k: _np(v) for k, v in model.interpolate(a, b, t).items()}
            return g["means"], g["quats"], g["scales"]
    return StateField(list(state_ids), np.stack([p["means"] for p in per]), np.stack([p["quats"] for p in per]),
                      np.stack([p["scales"] for p in per]), per[0]["colors"], per[0]["opacities"].reshape(-1),
                      deform=deform)


def _np(x: Any) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)
