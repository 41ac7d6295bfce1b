"""Settings of PD²GS part discovery, kinematics and meshing (one dataclass, every ablation switch).

Paper constants are the defaults where the paper gives one (2 % cluster merge, 10 positive / 20
negative prompts, r < 0.05 revolute rule). The paper gives no numbers for τ_mot, τ_vis, the TSDF voxel
size or the split minimum scale; ours are marked "ours" below. Units: metres (scene units), radians.

Two modes (docs/pd2gs-parts.md):

* ``mode="articulated"`` (default, ours): stage-1 field -> initial articulated model (counter, rigid-motion
  clusters, Kabsch joints) -> one articulated Gaussian fit of geometry, ownership and joints against every
  training view of every state -> model selection on held-out views -> meshes.
* ``mode="paper"`` (the paper's pipeline, kept as an ablation): stage-1 field -> trajectory clustering ->
  SAM-prompted refinement with boundary-aware splitting -> centre-based Kabsch joints with the paper's
  type rule -> meshes.

Ablation switches (docs/pd2gs-parts.md has the table):

* ``n_states``        — 2 or 4 (None = every state of the field): which interaction states are used.
* ``counter``         — "trajectory" (default, ours) | "motion" (ours) | "vlm" (the paper's) | "given" (oracle
  count from meta.json).
* ``fit_silhouette``  — articulated: weight of the object-silhouette loss (0 = RGB only).
* ``fit_depth``       — articulated: weight of a depth loss (0, the default: PD²GS is RGB-only).
* ``fit_ownership``   — articulated: "free" (default), "frozen" or "staged" (held for each fit's first half)
                        ownership during the fits.
* ``canonical``       — articulated: the canonical state, "widest" (default), "start", or both
                        ("widest,start": each discovered, the lowest held-out loss kept).
* ``select``          — articulated: False keeps the initial part count, tree and types.
* ``starts``          — articulated: the first joints (stage 1's Kabsch joints, the coarse joint search's,
                        the search on stage 1's rendered surfaces); each is discovered and the lowest
                        held-out loss (L1 + silhouette term) kept.
* ``refine``, ``mask_provider``, ``cluster``, ``split_disconnected`` — paper mode's segmentation.
* ``joint_rule``      — the Kabsch joints' type rule, "paper" or "bic" (None: the mode's own: "paper" in mode
  "paper", "bic" for the articulated initialisation).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Literal

from ..config_cli import ConfigError, check_choices


@dataclass
class VLMConfig:
    """An OpenAI-compatible chat-completions endpoint (``url`` = the full .../chat/completions URL).

    ``api_key_env`` names an environment variable holding the key (never the key itself).
    """

    url: str = ""
    """the full .../chat/completions URL."""
    model: str = "gpt-4o"
    """model name sent with each request."""
    api_key_env: str = "OPENAI_API_KEY"
    """environment variable holding the API key."""
    n_pairs: int = 5
    """image pairs shown to the model."""
    timeout_s: float = 60.0
    """seconds per request."""
    seed: int = 0
    """seed of the pair choice."""


STARTS = ("kabsch", "search", "surface")
"""the first joints mode "articulated" can start from (``DiscoveryConfig.starts``)."""
CANONICALS = ("widest", "start")
"""the rules that choose mode "articulated"'s canonical state (``DiscoveryConfig.canonical``)."""


def comma_list(value: str) -> list[str]:
    """"a, b,,c" -> ["a", "b", "c"] (a config field that names several choices)."""
    return [x.strip() for x in value.split(",") if x.strip()]


@dataclass
class DiscoveryConfig:
    """Every knob of ``pd2gs.discovery.pipeline.discover``."""

    mode: Literal["articulated", "paper"] = "articulated"
    """"articulated" (default, ours): one articulated Gaussian model fitted end to end; "paper": the paper's
    centre-based pipeline (ablation)."""

    # --- coarse segmentation (paper Sec. 3.3)
    tau_mot: float = 0.15
    """ours: fraction of the largest displacement that counts as motion."""
    min_cluster_frac: float = 0.02
    """paper: clusters < 2 % of dynamic Gaussians are merged."""
    kmeans_seed: int = 0
    """seed of k-means."""
    kmeans_n_init: int = 10
    """k-means restarts."""
    n_states: int | None = None
    """ablation: 2 or 4 states (None = all states of the field)."""
    cluster: Literal["trajectory", "rigid"] = "trajectory"
    """"trajectory": the paper's descriptor + k-means; "rigid": ours, by rigid motion."""
    split_disconnected: bool = False
    """ours: split clusters into spatially connected pieces (parts that always move together, e.g. equal
    drawers in multi-part states)."""

    canonical: str = "widest"
    """articulated: the state whose stage-1 Gaussians become the canonical geometry (joint values 0 there).
    "widest" (ours): the used state whose object silhouettes cover the most pixels on average, the most open
    one, where parts hidden in a closed state (a drawer's box, a tray) are seen; the start where no view has
    a mask. "start": the start state (the default until 2026-11-27). A comma list (``"widest,start"``) tries
    each rule that names a different state, every start of ``starts`` from each, and keeps the model with the
    lowest held-out loss, as among starts: where stage 1 moves a part in one state's Gaussians and not in
    another's (eyeglasses_rs-0000: none of the right temple's 623 Gaussians moves at the widest state), the
    held-out views choose (docs/pd2gs-experiments.md, twenty-eighth entry)."""

    # --- how many parts
    counter: Literal["trajectory", "motion", "vlm", "given"] = "trajectory"
    """part counter: "trajectory" local rigid motions + silhouette (default, ours); "motion" rigid RANSAC
    (ours); "vlm" the paper's; "given" the oracle count from meta.json (in mode articulated, model selection
    then keeps that count: no merges or prunes, only types and parents)."""
    count_min_opacity: float = 0.3
    """ours: only Gaussians at least this opaque vote on the part count."""
    min_silhouette: float = 0.35
    """ours: below it, one movable part (chosen on two trained demo fields, see docs). Mode "articulated"
    still starts from two clusters then and leaves one part or two to model selection."""
    given_count: int | None = None
    """for counter="given" (the pipeline fills it from meta.json)."""
    max_parts: int = 8
    """most movable parts a counter may return."""
    ransac_thresh_rel: float = 0.05
    """ours: inlier distance as a fraction of the largest displacement."""
    ransac_iters: int = 300
    """RANSAC iterations per rigid motion."""
    min_part_frac: float = 0.05
    """ours: a rigid motion needs this fraction of dynamic Gaussians."""
    vlm: VLMConfig = field(default_factory=VLMConfig)
    """the endpoint of counter="vlm"."""

    # --- refinement (paper Sec. 3.4, App. A.1)
    refine: bool = True
    """mode "paper": SAM-prompted refinement + boundary-aware splitting."""
    tau_vis: float = 2.0
    """ours: winner margin w_p / (max_q w_q + eps)."""
    vis_eps: float = 1e-6
    """the eps of that margin."""
    n_pos: int = 10
    """paper: positive prompts per part."""
    n_neg: int = 20
    """paper: negative prompts per part."""
    mask_provider: Literal["grabcut", "sam", "oracle"] = "grabcut"
    """mode "paper": part masks from "grabcut" (default), "sam" (segment_anything + a local checkpoint) or
    "oracle" (the dataset's true part masks)."""
    sam_checkpoint: str | None = None
    """path of a local SAM .pth file (mask_provider="sam")."""
    sam_model_type: str = "vit_b"
    """SAM model type of that checkpoint."""
    grabcut_iters: int = 5
    """GrabCut iterations per mask."""
    refine_views: int = 8
    """views per state used for prompts/masks (evenly spaced)."""
    axis_sigma: float = 2.0
    """ours: ellipse extent = axis_sigma standard deviations."""
    min_split_scale: float = 2e-3
    """ours: stop splitting below this std-dev (scene units)."""
    max_splits: int = 20000
    """most Gaussians split at a boundary."""
    vote_views: int = 5
    """views that vote on each child's label."""
    vote_depth_tol_rel: float = 0.01
    """ours: a view votes only if the child is within this (x extent) of the rendered surface (occluded
    Gaussians take no label from the masks)."""
    finetune: bool = True
    """fine-tune children's rotation + opacity (needs the rasterizer)."""
    finetune_iters: int = 200
    """fine-tuning steps."""
    finetune_lr: float = 0.01
    """fine-tuning learning rate."""
    background: tuple[float, float, float] | None = None
    """the trainer's render background (None = black)."""

    # --- kinematics (paper App. A.3, A.4)
    joint_rule: Literal["paper", "bic"] | None = None
    """type rule of the centre-based Kabsch joints: "paper" (residual rank) or "bic" (ours: translation vs
    rotation by BIC); None: the mode's own (mode "paper": "paper"; mode "articulated": "bic" for the initial
    joints, whose type model selection may swap). Both verdicts are always reported."""
    paper_r_thresh: float = 0.05
    """paper: r = (s2 + s3) / s1 < 0.05 -> revolute."""
    bic_noise_rel: float = 1e-3
    """ours: noise floor of the BIC rule (fraction of the part extent)."""
    robust_thresh_rel: float = 0.02
    """ours: RANSAC inlier threshold (fraction of the part extent)."""
    robust_iters: int = 200
    """RANSAC iterations of the rigid fit."""

    # --- the articulated model (mode "articulated"; pd2gs/articulated/)
    starts: str = "kabsch,search"
    """the first joints the articulated fit starts from, a comma list: ``kabsch`` (stage 1's Kabsch joints
    on its motion clusters), ``search`` (each body's joint searched by projection, all set together, hinge turns by
    rendering; pd2gs/articulated/search.py) and ``surface`` (each body's joint searched against the surfaces stage 1's
    field renders in each state, pd2gs/articulated/surfaces.py). Each start (times ``restarts``) is
    discovered to the end and the model with the lowest held-out loss kept (L1, plus the silhouette term at
    ``fit_silhouette`` where views have masks). ``surface`` is opt-in: on 15
    rsart-synth fields it lowers the penalised mean Axis Ang (true count: 23.4° -> 17.3°; counted: 17.2° ->
    14.2°) but with the counted part count it keeps spurious bodies (count accuracy 0.57 -> 0.43), and discovery
    takes 1.6x as long (docs/pd2gs-parts.md)."""
    fit_iters: int = 600
    """Adam steps of the articulated fit (one random training view per step)."""
    fit_max_side: int = 120
    """the fit's training views are rendered at most this large (intrinsics scaled). 120 rather than 80:
    on 15 rsart-synth objects, over two seeds, mean Axis Ang 8.9° / 8.6° against 12.7° / 20.0°, in the
    same discovery time (docs/pd2gs-parts.md)."""
    fit_silhouette: float = 0.5
    """weight of the L1 between rendered alpha and the view's object mask (0: RGB only)."""
    fit_depth: float = 0.0
    """weight of an L1 depth loss on pixels with a captured depth (0: RGB only, as PD²GS)."""
    fit_ownership: Literal["free", "frozen", "staged"] = "free"
    """who owns each Gaussian during the articulated fits: "free" (the soft ownership logits learn and a colour
    re-assignment runs every 100 steps), "frozen" (each Gaussian keeps the owner the start, or selection's
    edit, gave it; only geometry, appearance and joints are fitted) or "staged" (frozen for the first half of
    each fit's steps, free for the second: joints first, then ownership). Ablations (docs/pd2gs-experiments.md,
    thirty-fourth and thirty-fifth entries)."""
    fit_min_opacity: float = 0.02
    """stage-1 Gaussians less opaque than this are left out of the articulated model."""
    select: bool = True
    """model selection: merge / prune / re-parent / type swap while the penalised held-out loss improves."""
    select_penalty_rel: float = 0.02
    """cost of one movable body as a fraction of the held-out loss (mean L1 + ``fit_silhouette`` x mean
    |alpha - mask|) of the model entering selection (pd2gs/articulated/select.py)."""
    select_iters: int = 120
    """Adam steps of each candidate's re-fit."""
    select_rounds: int | None = None
    """at most this many accepted edits in each phase (None: the movable bodies entering selection + 2, as
    every merge or prune removes one; measured: a fixed 6 left drawer-0000 with three bodies for two)."""
    select_top: int = 3
    """candidates per round re-fitted (``select_iters`` steps) after screening by their score as built."""
    select_search_bodies: int = 0
    """re-parents found by the coarse joint search are offered while the model has at most this many movable
    bodies (0: none; each is one search, tens of seconds)."""
    final_iters: int = 300
    """Adam steps of the fit after selection (0: none)."""
    polish_iters: int = 600
    """Adam steps of a last fit of the chosen model (after the choice among starts) on views of at most
    ``polish_max_side`` px (0: none). The fit and selection run at ``fit_max_side``, where a pixel spans
    about 0.6 cm of a 0.7 m object. Measured on two rsart-synth fields (docs/pd2gs-experiments.md): a
    drawer 0.21 -> 0.15 deg, a door 1.34 -> 0.53 deg with its hinge line 31 -> 13 cm off, for about 45 s; it
    does not repair a joint that is wrong."""
    polish_max_side: int = 320
    """the polishing fit's views are at most this large (intrinsics scaled; never above the captured size)."""
    restarts: int = 1
    """articulated discovery runs from this many seeds (``seed``, ``seed`` + 1, ...); the model with the
    lowest held-out loss is kept (model selection over starts: the fit and selection end in different local
    optima from one seed to the next)."""

    # --- meshing (paper App. A.2)
    voxel_size: float | None = None
    """TSDF voxel size; None: object extent / 128."""
    sdf_trunc_voxels: float = 4.0
    """TSDF truncation in voxels."""
    depth_alpha_min: float = 0.5
    """pixels whose part alpha is lower carry no depth."""
    mesh_states: str = "start,end"
    """states whose meshes are written."""
    mesh_views: int = 24
    """train views per state rendered for TSDF fusion (evenly spaced)."""
    max_image_side: int = 320
    """views are rendered/segmented at most this large (intrinsics scaled)."""
    render_backend: Literal["cpu", "reference", "gsplat"] = "cpu"
    """rasterizer of the discovery renders."""
    seed: int = 0
    """seed of every random choice of the discovery."""

    def __post_init__(self) -> None:
        check_choices(self)
        for name, allowed in (("starts", STARTS), ("canonical", CANONICALS)):
            items = comma_list(getattr(self, name))
            if not items or len(set(items)) < len(items) or any(x not in allowed for x in items):
                raise ConfigError(f"{name}: {getattr(self, name)!r} must be a comma list of distinct "
                                  + ", ".join(repr(x) for x in allowed))
        if self.restarts < 1:
            raise ConfigError("restarts must be >= 1")
        if self.n_states is not None and self.n_states < 2:
            raise ConfigError("n_states must be >= 2 (motion needs two states)")
        if not 0.0 <= self.tau_mot <= 1.0:
            raise ConfigError("tau_mot must lie in [0, 1]")

    @property
    def start_list(self) -> list[str]:
        """``starts`` as a list."""
        return comma_list(self.starts)

    @property
    def canonical_list(self) -> list[str]:
        """``canonical`` as a list of rules."""
        return comma_list(self.canonical)

    def to_dict(self) -> dict:
        return asdict(self)
