"""The settings of a PD²GS training run: :class:`TrainConfig` (saved as RUN/config.json) and the
deformation network's :class:`DeformConfig`.

Their own module, free of torch, so that ``pd2gs --help`` builds its options from the fields
(pd2gs/config_cli.py) without loading the trainer. Units: pixels for image sizes, scene units
(metres) for lengths.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Literal

from pd2gs.config_cli import ConfigError, check_choices


@dataclass
class DeformConfig:
    """Network size (chosen for a 2-core CPU; see docs/pd2gs.md)."""

    latent_dim: int = 32
    """size of each state's latent code."""
    hidden: int = 64
    """hidden units per layer."""
    layers: int = 3
    """hidden layers."""
    pe_freqs: int = 6
    """positional-encoding frequencies of the canonical centres."""
    activation: Literal["leaky", "relu"] = "leaky"
    """hidden activation: "leaky" (ours: LeakyReLU with negative slope ``leaky_slope``) or "relu". With
    ReLU the last hidden layer died on the eyeglasses (0-4 of 64 units ever active, every state the
    same deformation, temples lost: 21.9 dB); LeakyReLU: 29.9 dB, temples moving (docs/pd2gs.md)."""
    leaky_slope: float = 0.01
    """negative slope of the LeakyReLU."""

    def __post_init__(self) -> None:
        check_choices(self)



@dataclass
class TrainConfig:
    """Everything that defines a run (saved as RUN/config.json)."""

    object_dir: str = ""
    """RS-Art object folder the run trains on (meta.json + states/*/cameras.json)."""
    states: list[str] = field(default_factory=list)
    """state ids trained on, in latent order (empty: every captured state)."""
    size: tuple[int, int] = (160, 120)
    """training image size (width, height) in pixels; intrinsics are scaled to it."""
    iters: int = 3000
    """training iterations."""
    backend: Literal["cpu", "reference", "gsplat"] = "cpu"
    """rasterizer: "cpu" (numba), "reference" (pure PyTorch), "gsplat" (CUDA, optional)."""
    seed: int = 0
    """seed of the initialisation, view order and densification."""
    init_points: int = 5000
    """initial Gaussians."""
    depth_init: bool = False
    """initialise from back-projected depth instead of the hull/box."""
    init: Literal["hull", "hull0", "box"] = "hull"
    """initial centres: "hull" the union of the per-state RGB-only visual hulls (ours, pd2gs/hull.py), "hull0"
    the hull of the first state only, "box" uniform in the box. Without the hull prior below, the hull start
    measured worse than the box on the suite (benchmarks/results/pd2gs-rsart-synth-init-hull.md); with it,
    it is what makes thin objects train (docs/pd2gs.md "Thin objects")."""
    init_union_frac: float = 0.0
    """init="hull0": this fraction of the points comes from the union hull."""
    background: tuple[float, float, float] | None = None
    """render background RGB in [0, 1]; None: estimated from the image borders."""
    deform: DeformConfig = field(default_factory=DeformConfig)
    """the deformation network."""
    lambda_dssim: float = 0.2
    """weight of the D-SSIM term in the photometric loss (1 - weight on L1)."""
    lr_means: float = 1.6e-3
    """learning rate of the centres, x scene extent, decays x0.01 over the run."""
    lr_log_scales: float = 5e-3
    """learning rate of the log scales."""
    lr_quats: float = 1e-3
    """learning rate of the rotations (quaternions)."""
    lr_colors: float = 1e-2
    """learning rate of the colours."""
    lr_opacity: float = 5e-2
    """learning rate of the opacity logits."""
    lr_mlp: float = 5e-3
    """learning rate of the deformation MLP; decays x0.1 over the run (5e-3 measured better than 1e-3 on
    storage-0001)."""
    lr_latents: float = 1e-2
    """learning rate of the per-state latent codes."""
    densify_from: int = 300
    """first iteration that densifies."""
    densify_until_frac: float = 0.6
    """densification stops at this fraction of ``iters``."""
    densify_every: int = 100
    """iterations between densification steps."""
    densify_grad: float = 2e-4
    """mean screen-space gradient above which a Gaussian is cloned or split."""
    percent_dense: float = 0.01
    """Gaussians larger than this fraction of the scene extent are split, smaller ones cloned."""
    min_opacity: float = 0.005
    """Gaussians below this opacity are pruned."""
    max_gaussians: int = 20000
    """densification cap."""
    opacity_reset_every: int = 1000
    """iterations between opacity resets."""
    checkpoint_every: int = 500
    """iterations between checkpoints (RUN/checkpoint.pt)."""
    threads: int = 2
    """torch threads."""
    curriculum: bool = False
    """ours (not in the paper; see docs/pd2gs.md "Training schedule"): states join one at a time in the
    order given, each new latent starting from its predecessor's, all active by curriculum_frac * iters.
    Measured worse on storage-0001 (docs/pd2gs.md)."""
    curriculum_frac: float = 0.4
    """with ``curriculum``: every state is active by this fraction of ``iters``."""
    rigidity_weight: float = 0.05
    """ours: weight of the local isometry prior on the deformation (pd2gs/rigidity.py); 0 disables it.
    0.2 and 0.02 measured worse on storage-0001 without the hull prior; 0.05 with it kept the eyeglasses'
    temples from sliding along themselves (docs/pd2gs.md "Thin objects")."""
    rigidity_k: int = 8
    """neighbours per Gaussian in the isometry prior."""
    scale_reg_weight: float = 1.0
    """ours: L1 penalty on the per-state log-scale offsets (parts move rigidly, they do not grow or shrink)."""
    hull_weight: float = 1.0
    """ours: per-state visual-hull prior (pd2gs/hull.py HullPrior; docs/pd2gs.md "Thin objects"): weight of
    the mean distance of the state's centres to its hull, fading linearly to 0 at hull_until_frac * iters."""
    hull_cover_weight: float = 1.0
    """ours: weight of the mean distance of hull voxels to the nearest opaque Gaussian (same fade)."""
    hull_until_frac: float = 0.8
    """the hull prior fades to 0 at this fraction of ``iters``."""
    hull_resolution: int = 64
    """voxels along the longest side of the hull grid."""
    hull_dilate: int = 1
    """grow the foreground masks by this many pixels before carving."""

    def __post_init__(self) -> None:
        check_choices(self)
        for name in ("iters", "init_points", "max_gaussians"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"TrainConfig.{name} must be positive, got {getattr(self, name)}")

    @staticmethod
    def from_json(d: dict) -> "TrainConfig":
        d = dict(d)
        d["deform"] = DeformConfig(**{"activation": "relu", **d.get("deform", {})})  # configs from before `activation` existed: ReLU
        d["size"] = tuple(d["size"])
        if d.get("background") is not None:
            d["background"] = tuple(d["background"])
        for key in ("hull_weight", "hull_cover_weight"):  # runs written before the prior existed
            d.setdefault(key, 0.0)
        d.setdefault("hull_dilate", 0)
        names = {f.name for f in dataclasses.fields(TrainConfig)}
        return TrainConfig(**{k: v for k, v in d.items() if k in names})
