"""PD²GS part discovery on one trained object, as one pipeline of steps, each its own function:

    stage 1 -> initialisation -> articulated fit -> model selection -> meshes -> ObjectResult

(``mode="articulated"``, the default), or the paper's pipeline, kept as an ablation (``mode="paper"``):

    stage 1 -> trajectory clustering -> SAM-prompted refinement -> centre-based Kabsch joints -> meshes

    from pd2gs.discovery.pipeline import discover, discover_safe, method_block
    from pd2gs.discovery.submission import write_submission
    res = discover(field_or_model, rsart.load("data/obj"), DiscoveryConfig())
    write_submission({obj.id: res}, "out/sub", method_block(cfg))

``field_or_model``: a :class:`~pd2gs.discovery.field.StateField` or a trained model with
``state_gaussians(state_id)`` (see :func:`~pd2gs.discovery.field.as_state_field`). The steps share one
:class:`Discovery` record.
"""
from __future__ import annotations

import copy
import dataclasses
import logging
import time
import traceback
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import torch

import pd2gs
from pd2gs.articulated.fit import FitConfig, fit_articulated, held_out_loss, view_errors
from pd2gs.articulated.model import ArticulatedGaussians
from pd2gs.articulated.search import SearchConfig, search_joints
from pd2gs.articulated.select import SelectConfig, select_model
from pd2gs.articulated.surfaces import SurfaceViews, field_surfaces, search_surfaces
from pd2gs.data import Frame
from pd2gs.kinematics import JointFit, estimate_joint
from rsart.camera import Camera

from . import motion
from .config import DiscoveryConfig
from .field import StateField, as_state_field
from .initialise import count_parts, init_from_field
from .masks import make_provider, sample_prompts, visibility_sets
from .meshing import clean_mesh, render_depth, tsdf_fuse
from .refine import boundary_split
from .submission import ObjectFailure, ObjectResult, PartResult

log = logging.getLogger(__name__)


@dataclass
class Discovery:
    """What the steps of one object's discovery share.

    ``fld``: the stage-1 per-state Gaussians of the used ``states`` (replaced by the articulated model's
    posed Gaussians after the fit); ``labels`` (N,) 0 = static base, 1..K movable parts of ``fld``;
    ``joints``: label -> joint (world frame at the ``start`` state, values relative to it); ``model``: the
    articulated model (mode "articulated"); ``frames``/``masks``: its training and held-out views and
    their object silhouettes; ``diag``: diagnostics written to the result.
    """

    obj: Any
    cfg: DiscoveryConfig
    states: list[str]
    start: str
    end: str
    fld: StateField
    labels: np.ndarray | None = None
    joints: dict[int, JointFit] = field(default_factory=dict)
    model: ArticulatedGaussians | None = None
    ref_index: int = 0
    frames: list[Frame] = field(default_factory=list)
    masks: list[torch.Tensor | None] = field(default_factory=list)
    stage1_means: np.ndarray | None = None
    diag: dict[str, Any] = field(default_factory=dict)


# ----------------------------------------------------------------------------- states and views
def used_states(obj, field_states: list[str], n_states: int | None) -> list[str]:
    """States used for discovery, in meta.json order: all field states, or 2 (start, end), or the first
    n multi-part states (start and end always included)."""
    ev = obj.meta.eval_states
    order = [s.id for s in obj.meta.states if s.id in field_states]
    if n_states is None:
        return order
    if n_states == 2:
        return [ev["start"], ev["end"]]
    multi = [s.id for s in obj.meta.states if s.kind == "multi" and s.id in field_states]
    pick = [s for s in multi if s in (ev["start"], ev["end"])]
    for s in multi:
        if len(pick) >= n_states:
            break
        if s not in pick:
            pick.append(s)
    return [s for s in order if s in pick]


def pick_views(obj, state_id: str, n: int, max_side: int) -> list[tuple[str, Camera, Any]]:
    """n evenly spaced train views (view id, camera scaled to at most ``max_side`` px, View record)."""
    st = obj.states[state_id]
    views = st.split("train") or st.views
    idx = np.unique(np.linspace(0, len(views) - 1, min(n, len(views))).round().astype(int))
    out = []
    for i in idx:
        v = views[i]
        cam = v.camera
        s = min(1.0, max_side / max(cam.width, cam.height))
        if s < 1.0:
            cam = cam.scaled(max(1, round(cam.width * s)), max(1, round(cam.height * s)))
        out.append((v.id, cam, v))
    return out


def _resize(img: np.ndarray, cam: Camera, nearest: bool = False) -> np.ndarray:
    if img.shape[:2] == (cam.height, cam.width):
        return img
    return cv2.resize(img, (cam.width, cam.height), interpolation=cv2.INTER_NEAREST if nearest else cv2.INTER_AREA)


def _t(a) -> torch.Tensor:
    return torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)


# ----------------------------------------------------------------------------- steps
def refine_parts(fld: StateField, labels: np.ndarray, obj, states: list[str], ref: str, cfg: DiscoveryConfig
                 ) -> tuple[StateField, np.ndarray, dict]:
    """Visibility prompts -> masks -> boundary-aware splitting (-> fine-tune) in the reference state."""
    from pd2gs.render import rasterize

    k = fld.index(ref)
    L = int(labels.max()) + 1
    provider = make_provider(cfg.mask_provider, grabcut_iters=cfg.grabcut_iters, sam_checkpoint=cfg.sam_checkpoint,
                             sam_model_type=cfg.sam_model_type, seed=cfg.seed)
    views = pick_views(obj, ref, cfg.refine_views, cfg.max_image_side)
    cams, part_masks, visible, depths = [], [], [], []
    for vid, cam, view in views:
        with torch.no_grad():
            out = rasterize(_t(fld.means[k]), _t(fld.quats[k]), _t(fld.scales[k]), _t(fld.colors),
                            _t(fld.opacities), _t(cam.K), _t(cam.w2c), cam.width, cam.height,
                            backend=cfg.render_backend, labels=torch.as_tensor(labels), num_labels=L,
                            return_max_weight=True)
        lw = out.label_weights.numpy()
        rgb = _resize(view.rgb, cam)
        true_mask = _resize(view.mask, cam, nearest=True) if cfg.mask_provider == "oracle" else None
        masks = {}
        for p in range(L):
            pos, neg = visibility_sets(lw, p, cfg.tau_vis, cfg.vis_eps)
            if not pos.any():
                continue
            ppos, pneg = sample_prompts(pos, neg, cfg.n_pos, cfg.n_neg, cfg.seed)
            masks[p] = provider(rgb, ppos, pneg, support=pos, true_mask=true_mask, view_key=(ref, vid))
        cams.append(cam)
        part_masks.append(masks)
        visible.append(out.max_weight.numpy() > 0)
        depths.append(np.where(out.alpha.numpy() > cfg.depth_alpha_min, out.depth.numpy(), 0.0))
    extent = float(np.linalg.norm(np.ptp(fld.means[k], axis=0)))
    sr = boundary_split(fld, labels, k, cams, part_masks, np.stack(visible), cfg.axis_sigma, cfg.min_split_scale,
                        cfg.max_splits, cfg.vote_views, depths, cfg.vote_depth_tol_rel * extent)
    diag = {"candidates": sr.n_candidates, "splits": sr.n_splits, **sr.stats}
    if cfg.finetune and len(sr.children):
        from .finetune import finetune_children
        tv = [[(cam, _resize(view.rgb, cam)) for _, cam, view in pick_views(obj, s, cfg.refine_views,
                                                                           min(cfg.max_image_side, 160))]
              for s in sr.field.state_ids]
        diag["finetune"] = finetune_children(sr.field, sr.children, tv, cfg.finetune_iters, cfg.finetune_lr,
                                             cfg.seed, cfg.render_backend, cfg.background)
    return sr.field, sr.labels, diag


def part_meshes(fld: StateField, labels: np.ndarray, obj, sid: str, cfg: DiscoveryConfig, voxel: float
                ) -> tuple[dict[int, Any], Any]:
    """TSDF meshes of every label and of the whole object in state ``sid`` -> ({label: mesh}, whole)."""
    k = fld.index(sid)
    views = pick_views(obj, sid, cfg.mesh_views, cfg.max_image_side)
    cams = [c for _, c, _ in views]
    out = {}
    groups = {p: labels == p for p in np.unique(labels)}
    groups[-1] = np.ones(len(labels), dtype=bool)
    for p, sel in groups.items():
        depths = [render_depth(fld.means[k][sel], fld.quats[k][sel], fld.scales[k][sel], fld.colors[sel],
                               fld.opacities[sel], c, cfg.depth_alpha_min, cfg.render_backend)[0] for c in cams]
        out[int(p)] = clean_mesh(tsdf_fuse(depths, cams, voxel, cfg.sdf_trunc_voxels))
    whole = out.pop(-1)
    return out, whole


# ----------------------------------------------------------------------------- stage 1
def stage1(field_or_model: Any, obj, cfg: DiscoveryConfig) -> Discovery:
    """The used states of the trained field (``cfg.n_states``; start and end always) -> a Discovery."""
    ev = obj.meta.eval_states
    all_states = getattr(field_or_model, "state_ids", None)  # a StateField, or a model that lists its states
    if all_states is None:                                   # else: the multi-part states (the paper trains on them)
        all_states = [s.id for s in obj.meta.states if s.kind == "multi"]
    states = used_states(obj, list(all_states), cfg.n_states)
    for s in (ev["start"], ev["end"]):
        if s not in states:
            raise ObjectFailure(f"the field has no {s!r} state (eval_states needs it; field states: {list(all_states)})")
    fld = as_state_field(field_or_model, states)
    return Discovery(obj, cfg, states, ev["start"], ev["end"], fld, diag={"mode": cfg.mode, "states": states,
                                                                         "n_gaussians": fld.n})


# ----------------------------------------------------------------------------- mode "articulated"
def training_views(obj, states: list[str], cfg: DiscoveryConfig) -> tuple[list[Frame], list[torch.Tensor | None]]:
    """Every captured view of the used states, at most ``cfg.fit_max_side`` px (intrinsics scaled), keeping
    the dataset's train/test split -> (frames, per frame the object silhouette (H, W) in {0, 1} = mask > 0,
    or None where the view has no mask or ``cfg.fit_silhouette`` is 0). Depth is read only when
    ``cfg.fit_depth`` > 0. A state with no ``test`` view lends every fifth train view to model selection."""
    frames: list[Frame] = []
    masks: list[torch.Tensor | None] = []
    for k, sid in enumerate(states):
        views = obj.states[sid].views
        has_test = any(v.split == "test" for v in views)
        for i, v in enumerate(views):
            cam = v.camera
            s = min(1.0, cfg.fit_max_side / max(cam.width, cam.height))
            if s < 1.0:
                cam = cam.scaled(max(1, round(cam.width * s)), max(1, round(cam.height * s)))
            rgb = torch.from_numpy(_resize(v.rgb, cam).astype(np.float32) / 255.0)
            depth = None
            if cfg.fit_depth > 0 and v.has_depth:
                depth = torch.from_numpy(_resize(v.depth, cam, nearest=True).astype(np.float32))
            split = v.split if has_test else ("test" if i % 5 == 4 else "train")
            frames.append(Frame(rgb, depth, _t(cam.K), _t(cam.w2c), k, split, v.id))
            mask = None
            if cfg.fit_silhouette > 0 and v.has_mask:
                mask = torch.from_numpy((_resize(v.mask, cam, nearest=True) > 0).astype(np.float32))
            masks.append(mask)
    return frames, masks


def fit_config(d: Discovery, iters: int) -> FitConfig:
    """The articulated fit's settings for this object (its gauge state, background, loss weights, and whether
    ownership may move: ``cfg.fit_ownership`` holds it for none, all or the first half of the ``iters`` steps)."""
    c = d.cfg
    held = {"free": 0, "frozen": iters, "staged": iters // 2}[c.fit_ownership]
    return FitConfig(iters=iters, silhouette=c.fit_silhouette, depth=c.fit_depth, ref_state=d.ref_index,
                     background=tuple(c.background) if c.background is not None else (0.0, 0.0, 0.0),
                     backend=c.render_backend, seed=c.seed, ownership_warmup=held)


def canonical_state(d: Discovery, rule: str | None = None) -> str:
    """The state a canonical ``rule`` (default: the first of ``cfg.canonical``) names: "start", or "widest":
    the used state whose views' object masks cover the largest mean fraction of the image (the start when no
    view of a used state has a mask)."""
    rule = rule or d.cfg.canonical_list[0]
    if rule == "start" or d.obj is None:
        return d.start
    area = {}
    for s in d.states:
        cover = [float((v.mask > 0).mean()) for v in d.obj.states[s].views if v.has_mask]
        if not cover:
            return d.start
        area[s] = float(np.mean(cover))
    best = max(d.states, key=lambda s: (area[s], s == d.start))
    d.diag["canonical"] = {"state": best, "mask_area": area}
    return best


def canonical_states(d: Discovery) -> list[str]:
    """The distinct states the rules of ``cfg.canonical`` name, in its order."""
    out: list[str] = []
    for rule in d.cfg.canonical_list:
        s = canonical_state(d, rule)
        if s not in out:
            out.append(s)
    return out


def initialise(d: Discovery, ref: str | None = None) -> None:
    """Part count, rigid-motion clusters and Kabsch joints of stage 1 -> the first (flat) articulated model,
    canonical at ``ref`` (default: :func:`canonical_state`)."""
    ref = ref or canonical_state(d)
    d.diag.setdefault("canonical", {})["state"] = ref
    other = d.end if ref != d.end else d.start  # the state whose initial values are made positive
    init = init_from_field(d.fld, d.states, ref, other, cfg=d.cfg, obj=d.obj, min_opacity=d.cfg.fit_min_opacity)
    d.diag["count"] = init.count
    if init.model.num_bodies < 2:
        raise ObjectFailure(f"no movable part found (count {init.count.get('n')}, "
                            f"{int(motion.dynamic_mask(d.fld.means, d.cfg.tau_mot).sum())} dynamic Gaussians)")
    d.model, d.ref_index = init.model, init.ref_index
    d.stage1_means = d.fld.means[:, init.keep]
    d.diag["init"] = {"bodies": init.model.num_bodies, "n_gaussians": int(init.keep.sum()),
                      "sizes": np.bincount(init.labels).tolist()}


def search(d: Discovery) -> None:
    """Each body's joint chosen by how well the posed Gaussians agree with the training views (all bodies
    at once, hinge turns by rendering), kept where the held-out views agree too
    (:mod:`pd2gs.articulated.search`); ownership is left to the fit."""
    t0 = time.perf_counter()
    fc = fit_config(d, 0)
    res = search_joints(d.model, d.frames, d.masks, d.ref_index,
                        SearchConfig(silhouette=fc.silhouette, background=fc.background, backend=fc.backend))
    d.diag["search"] = {"seconds": time.perf_counter() - t0, "bodies": res.chosen,
                        "held_out": res.held_out, "kept": res.kept}


def surface_search(d: Discovery) -> None:
    """Each body's joint chosen against the object's surface in every state, as stage 1's field renders it
    (:mod:`pd2gs.articulated.surfaces`); ownership is left to the fit."""
    t0 = time.perf_counter()
    f = d.fld
    gaussians = [{"means": f.means[k], "quats": f.quats[k], "scales": f.scales[k], "colors": f.colors,
                  "opacities": f.opacities} for k in range(f.k)]
    surfaces = SurfaceViews(field_surfaces(gaussians, d.frames, backend=d.cfg.render_backend))
    res = search_surfaces(d.model, surfaces, d.ref_index, SearchConfig())
    d.diag["surface"] = {"seconds": time.perf_counter() - t0, "bodies": res.chosen}


def fit(d: Discovery) -> None:
    """Geometry, ownership and joints fitted together on every training view of every state."""
    res = fit_articulated(d.model, d.frames, d.masks, fit_config(d, d.cfg.fit_iters))
    d.diag["fit"] = {"seconds": res.seconds, "loss_first_last": [res.losses[0], res.losses[-1]],
                     "reassigned": res.reassigned}


def select(d: Discovery) -> None:
    """Model selection on the held-out views (merge / prune / re-parent / type swap), then a last fit."""
    t0 = time.perf_counter()
    sel = select_model(d.model, d.frames, d.masks,
                       SelectConfig(penalty_rel=d.cfg.select_penalty_rel, refit=fit_config(d, d.cfg.select_iters),
                                    max_rounds=d.cfg.select_rounds, refit_top=d.cfg.select_top,
                                    search_max_bodies=d.cfg.select_search_bodies,
                                    keep_count=d.cfg.counter == "given"),
                       d.stage1_means)
    d.model = sel.model
    d.diag["select"] = {"seconds": time.perf_counter() - t0, "score": sel.score, "log": sel.log}
    if d.cfg.final_iters > 0:
        res = fit_articulated(d.model, d.frames, d.masks, fit_config(d, d.cfg.final_iters))
        d.diag["final_fit"] = {"seconds": res.seconds, "loss_first_last": [res.losses[0], res.losses[-1]]}


@torch.no_grad()
def posed_field(model: ArticulatedGaussians, states: list[str]) -> StateField:
    """The hard-owned model posed in each training state as a StateField (labels = owners); its ``deform``
    poses the joint values interpolated between two states (unseen states by posing the joints)."""
    model.harden()
    g = model.gaussians
    posed = [model.pose(k) for k in range(len(states))]
    scales = torch.exp(g.log_scales).double().numpy()

    @torch.no_grad()
    def deform(a: str, b: str, t: float):
        v = (1 - t) * model.values[states.index(a)] + t * model.values[states.index(b)]
        m, q = model.pose(values=v)
        return m.double().numpy(), q.double().numpy(), scales

    return StateField(list(states), np.stack([m.double().numpy() for m, _ in posed]),
                      np.stack([q.double().numpy() for _, q in posed]), np.tile(scales, (len(states), 1, 1)),
                      g.colors.detach().double().numpy(), g.opacities.detach().double().numpy().reshape(-1),
                      model.labels().numpy(), deform)


@torch.no_grad()
def model_joints(model: ArticulatedGaussians, states: list[str], start: str, end: str) -> dict[int, JointFit]:
    """Each movable body's joint as the submission writes it: axis and pivot in the world frame at ``start``
    (the parent posed there; the canonical frame may be another state's), values per state relative to its
    parent and 0 at ``start``, the axis signed so the ``end`` value is positive. Both Kabsch type rules are
    evaluated on the body's posed centres in its parent's frame and reported beside the fitted type."""
    s0, s1 = states.index(start), states.index(end)
    lab = model.labels()
    out = {}
    bp0 = model.body_poses(s0)
    for b in range(1, model.num_bodies):
        j, p = b - 1, model.parent[b]
        Rp, tp = bp0.R[p].double(), bp0.t[p].double()
        axis = (Rp @ model.unit_axes[j].double()).numpy()
        vals = model.values[:, j].double().numpy()
        vals = vals - vals[s0]
        if vals[s1] < 0:
            axis, vals = -axis, -vals
        own = lab == b
        origin = (Rp @ model.pivots[j].double() + tp).numpy()
        if model.joint_types[j] == "prismatic" and bool(own.any()):
            x0 = model.gaussians.means[own].double().mean(0)
            origin = (bp0.R[b].double() @ x0 + bp0.t[b].double()).numpy()
        rel = []
        for k in range(len(states)):
            bp = model.body_poses(k)
            x = (bp.R[b] @ model.gaussians.means[own].T).T + bp.t[b]
            rel.append(((x - bp.t[p]) @ bp.R[p]).double().numpy())
        kabsch = estimate_joint(np.stack(rel), states, start, end, "bic") if own.sum() >= 3 else None
        out[b] = JointFit(model.joint_types[j], axis, origin, {s: float(vals[k]) for k, s in enumerate(states)},
                          "articulated", kabsch.type_paper if kabsch else model.joint_types[j],
                          kabsch.type_bic if kabsch else model.joint_types[j],
                          {"parent": int(p), "n_gaussians": int(own.sum())})
    return out


def articulated_parts(d: Discovery) -> None:
    """Mode "articulated": per canonical state of ``cfg.canonical`` (:func:`canonical_states`), seed
    (``cfg.restarts``) and start of ``cfg.starts``: initialise -> (coarse joint search) -> fit -> select ->
    the posed model's field, labels and joints; the run with the lowest held-out loss (``diag["test_loss"]``,
    the one model selection scores: L1 plus the silhouette term) is kept, every run's in ``diag["starts"]``
    when there was more than one (:func:`discover_starts`). A canonical state where no movable part is found
    is skipped while another one is left."""
    d.frames, d.masks = training_views(d.obj, d.states, d.cfg)
    runs: list[tuple[str, Discovery, dict]] = []  # (start, run, note: "fit_of" = index of the run it shares)
    refs = canonical_states(d)
    failed: list[tuple[str, ObjectFailure]] = []
    for ref in refs:
        for k in range(d.cfg.restarts):
            base = dataclasses.replace(d, cfg=dataclasses.replace(d.cfg, seed=d.cfg.seed + k),
                                       diag=copy.deepcopy(d.diag))
            try:
                initialise(base, ref)
            except ObjectFailure as e:  # no movable part from this state: it is skipped, its other seeds too
                failed.append((ref, e))
                break
            discover_starts(base, runs, {"canonical": ref} if len(refs) > 1 else {})
    if not runs:
        if len(failed) == 1:
            raise failed[0][1]
        raise ObjectFailure("; ".join(f"canonical {ref}: {e}" for ref, e in failed))
    chosen = min(range(len(runs)), key=lambda i: runs[i][1].diag["test_loss"])
    best = runs[chosen][1]
    for f in dataclasses.fields(Discovery):
        if f.name != "cfg":
            setattr(d, f.name, getattr(best, f.name))
    if len(runs) > 1:
        d.diag["starts"] = {"runs": [{"start": s, "seed": r.cfg.seed, "test_l1": r.diag["test_l1"],
                                      "test_loss": r.diag["test_loss"], **note}
                                     for s, r, note in runs], "chosen": chosen,
                             **({"failed": [f"canonical {ref}: {e}" for ref, e in failed]} if failed else {})}
    if d.cfg.polish_iters > 0:
        polish(d)
        read_model(d)


def discover_starts(base: Discovery, runs: list[tuple[str, Discovery, dict]], note: dict) -> None:
    """Every start of ``cfg.starts`` from the initialised ``base``: (coarse joint search) -> fit -> select,
    each appended to ``runs`` as (start, run, ``note`` + the start's own notes). A search that keeps nothing
    leaves the initial model as it was, so that start shares the Kabsch start's fit ("fit_of": its index in
    ``runs``) instead of repeating it."""
    plain: int | None = None  # index in runs of the fit from the initial model as it is
    pending: list[Discovery] = []  # the runs to fit (:func:`fit_starts`)
    starts = base.cfg.start_list
    for i, start in enumerate(starts):
        last = i == len(starts) - 1  # (the last start takes the model itself: no copy to fit)
        run = base if last else dataclasses.replace(base, model=copy.deepcopy(base.model),
                                                    diag=copy.deepcopy(base.diag))
        own = dict(note)
        if start == "search":
            search(run)
            own["search_kept"] = run.diag["search"]["kept"]
        elif start == "surface":
            surface_search(run)
        changed = start == "surface" or own.get("search_kept", False)
        if not changed and plain is not None:
            # a search that kept nothing restored the initial model bitwise: its fit would repeat this one
            runs.append((start, runs[plain][1], {**own, "fit_of": plain}))
            continue
        if not changed:
            plain = len(runs)
        pending.append(run)
        runs.append((start, run, own))
    fit_starts(pending)


def fit_starts(runs: list[Discovery]) -> None:
    """From initialised (and maybe searched) models: :func:`fit_and_select`, then :func:`read_model`, on each
    run, in place. With two or more CPU threads (``torch.get_num_threads()``) and two or more runs, the runs'
    fit and selection run side by side, the threads shared out
    (:mod:`pd2gs.discovery.side_by_side`); one thread each is also what every run gets in a suite run with one
    thread per object, so both give the same models."""
    threads = torch.get_num_threads()
    n = min(len(runs), threads)
    done = None
    if n >= 2:
        from .side_by_side import run_side_by_side

        kept = [(run.obj, run.fld) for run in runs]
        for run in runs:
            run.obj = run.fld = None  # neither is read by the fit or selection, and the field does not pickle
        try:
            done = run_side_by_side(fit_and_select, runs, threads // n, n)
        finally:
            for run, (obj, fld) in zip(runs, kept):
                run.obj, run.fld = obj, fld
    for i, run in enumerate(runs):
        if done is None:
            fit_and_select(run)
        else:
            run.model, run.diag = done[i].model, done[i].diag
        read_model(run)


def polish(d: Discovery) -> None:
    """The chosen model fitted ``cfg.polish_iters`` more steps on views of at most ``cfg.polish_max_side``
    px. The fit and selection run at ``fit_max_side`` (120 px), where a pixel spans about 0.6 cm of a
    0.7 m object: coarser than the joint targets (a hinge within 1 cm, a turn within 2°)."""
    t0 = time.perf_counter()
    frames, masks = training_views(d.obj, d.states, dataclasses.replace(d.cfg, fit_max_side=d.cfg.polish_max_side))
    res = fit_articulated(d.model, frames, masks, fit_config(d, d.cfg.polish_iters))
    d.diag["polish"] = {"seconds": time.perf_counter() - t0, "max_side": d.cfg.polish_max_side,
                        "loss_first_last": [res.losses[0], res.losses[-1]]}


def fit_and_select(d: Discovery) -> None:
    """:func:`fit`, then :func:`select` unless ``cfg.select`` is off (neither reads ``d.obj`` or ``d.fld``)."""
    fit(d)
    if d.cfg.select:
        select(d)


def read_model(d: Discovery) -> None:
    """The fitted model's posed field, labels and joints (a body too small to mesh joins its parent), its
    held-out L1 and loss on ``d.frames`` (L1 + silhouette term: what selection scores) and its tree."""
    d.fld = posed_field(d.model, d.states)
    labels = d.fld.labels.copy()
    joints = model_joints(d.model, d.states, d.start, d.end)
    for b in range(d.model.num_bodies - 1, 0, -1):  # children first: a body too small to mesh joins its parent
        if (labels == b).sum() < 3:
            labels[labels == b] = d.model.parent[b]
            joints.pop(b, None)
    d.fld.labels = d.labels = labels
    d.joints = joints
    fc = fit_config(d, 0)
    l1, sil = view_errors(d.model, d.frames, "test", fc.background, fc.backend, d.masks)  # one render per view
    d.diag["test_l1"] = held_out_loss(l1, sil, 0.0)
    d.diag["test_loss"] = held_out_loss(l1, sil, fc.silhouette)
    d.diag["tree"] = {f"p{b}": (f"p{p}" if p else "static") for b, p in enumerate(d.model.parent) if b in joints}


# ----------------------------------------------------------------------------- mode "paper"
def paper_parts(d: Discovery) -> None:
    """Mode "paper": count, trajectory clustering, refinement, centre-based Kabsch joints (the paper's type rule
    unless ``cfg.joint_rule`` names another)."""
    cfg, fld = d.cfg, d.fld
    dyn = motion.dynamic_mask(fld.means, cfg.tau_mot)
    d.diag["n_dynamic"] = int(dyn.sum())
    n_parts, cdiag = count_parts(fld, dyn, d.obj, d.states, cfg)
    d.diag["count"] = {"n": n_parts, **cdiag}
    if n_parts < 1 or not dyn.any():
        raise ObjectFailure(f"no movable part found ({int(dyn.sum())} dynamic Gaussians, count {n_parts})")
    labels = motion.coarse_labels(fld.means, n_parts, cfg.tau_mot, cfg.min_cluster_frac, cfg.kmeans_seed,
                                  cfg.kmeans_n_init, cfg.cluster)
    if cfg.split_disconnected:
        labels = motion.split_disconnected(fld.means[fld.index(d.start)], labels,
                                           max(3, int(cfg.min_cluster_frac * max(1, int(dyn.sum())))))
        d.diag["count"]["after_spatial_split"] = int(labels.max())
    d.diag["coarse_sizes"] = np.bincount(labels).tolist()
    if cfg.refine:
        fld, labels, d.diag["refine"] = refine_parts(fld, labels, d.obj, d.states, d.start, cfg)
    fld.labels = labels
    d.fld, d.labels = fld, labels
    d.joints = {p: estimate_joint(fld.means[:, labels == p], fld.state_ids, d.start, d.end, cfg.joint_rule or "paper",
                                  cfg.paper_r_thresh, cfg.bic_noise_rel, cfg.robust_thresh_rel, cfg.robust_iters,
                                  cfg.seed)
                for p in range(1, int(labels.max()) + 1) if (labels == p).sum() >= 3}


# ----------------------------------------------------------------------------- meshes and the result
def result(d: Discovery, t0: float) -> ObjectResult:
    """TSDF meshes of every part and the whole object in the mesh states -> the ObjectResult."""
    cfg, fld, labels = d.cfg, d.fld, d.labels
    ref_means = fld.means[fld.index(d.start)]
    extent = float(np.linalg.norm(np.ptp(ref_means, axis=0)))
    voxel = cfg.voxel_size or extent / 128
    ev = d.obj.meta.eval_states
    mesh_states = [ev.get(s, s) for s in cfg.mesh_states.split(",")]
    meshes = {sid: part_meshes(fld, labels, d.obj, sid, cfg, voxel) for sid in mesh_states}
    parts = [PartResult("static", 0, {sid: meshes[sid][0].get(0) for sid in mesh_states})]
    parts += [PartResult(f"p{p}", p, {sid: meshes[sid][0].get(p) for sid in mesh_states}, j)
              for p, j in d.joints.items()]
    d.diag["seconds"] = time.perf_counter() - t0
    d.diag["joints"] = {p.name: {"type": p.joint.type, "type_paper": p.joint.type_paper,
                                 "type_bic": p.joint.type_bic, **p.joint.diagnostics}
                        for p in parts if p.joint is not None}
    return ObjectResult(d.obj.meta.object_id, parts, {sid: meshes[sid][1] for sid in mesh_states}, d.diag, fld)


# ----------------------------------------------------------------------------- the pipeline
def discover(field_or_model: Any, obj, config: DiscoveryConfig | None = None) -> ObjectResult:
    """Parts, joints and meshes of one object (an ``rsart.load`` RSArtObject) from its trained field."""
    t0 = time.perf_counter()
    d = stage1(field_or_model, obj, config or DiscoveryConfig())
    if d.cfg.mode == "paper":
        paper_parts(d)
    else:
        articulated_parts(d)
    return result(d, t0)

def discover_safe(field_or_model: Any, obj, config: DiscoveryConfig | None = None) -> ObjectResult | ObjectFailure:
    """:func:`discover` that returns an ObjectFailure (reason + traceback logged) instead of raising."""
    try:
        return discover(field_or_model, obj, config)
    except Exception as e:  # a failed object becomes null in the submission, never a crash
        log.error("%s: discovery failed: %s\n%s", getattr(obj, "id", "?"), e, traceback.format_exc())
        return e if isinstance(e, ObjectFailure) else ObjectFailure(f"{type(e).__name__}: {e}")


def method_block(cfg: DiscoveryConfig, states_used: int | None = None) -> dict:
    """The submission's ``method`` object for these settings (ablation flags included)."""
    art = cfg.mode == "articulated"
    inputs = ["rgb"] + (["mask"] if art and cfg.fit_silhouette > 0 else []) + (["depth"] if art and cfg.fit_depth > 0 else [])
    return {"name": "PD2GS", "version": pd2gs.__version__, "inputs": inputs, "camera_poses": "gt",
            "states_used": states_used if states_used is not None else (cfg.n_states or "all"),
            "discovery": {"mode": cfg.mode, "counter": cfg.counter, "n_states": cfg.n_states,
                          **({"refine": cfg.refine, "mask_provider": cfg.mask_provider, "cluster": cfg.cluster,
                              "joint_rule": cfg.joint_rule or "paper"} if cfg.mode == "paper" else
                             {"silhouette": cfg.fit_silhouette, "depth": cfg.fit_depth, "select": cfg.select,
                              "fit_max_side": cfg.fit_max_side, "fit_iters": cfg.fit_iters,
                              "select_penalty_rel": cfg.select_penalty_rel, "select_iters": cfg.select_iters,
                              "select_rounds": cfg.select_rounds, "select_top": cfg.select_top,
                              "select_search_bodies": cfg.select_search_bodies, "canonical": cfg.canonical,
                              "seed": cfg.seed, "final_iters": cfg.final_iters,
                              "polish_iters": cfg.polish_iters, "polish_max_side": cfg.polish_max_side,
                              "joint_rule": cfg.joint_rule or "bic", "starts": cfg.starts,
                              "restarts": cfg.restarts, "fit_ownership": cfg.fit_ownership})}}


def dataset_block(data: str) -> dict:
    """The submission's ``dataset`` object for a dataset root (``index.json``: name, version), or {} for a
    single object folder (then rsart-eval checks no name)."""
    from pathlib import Path

    from rsart.format import read_index

    idx = Path(data) / "index.json"
    if not idx.is_file():
        return {}
    index = read_index(idx)
    return {"name": index.name, "version": index.version}
