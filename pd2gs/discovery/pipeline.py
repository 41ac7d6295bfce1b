"""PD²GS part discovery end to end on one trained object: parts -> refinement -> kinematics -> meshes.

    from pd2gs.discovery.pipeline import discover, discover_safe, method_block
    from pd2gs.discovery.submission import write_submission
    res = discover(field_or_model, rsart.load("data/obj"), DiscoveryConfig())
    write_submission({obj.id: res}, "out/sub", method_block(cfg, res))

``field_or_model``: a :class:`~pd2gs.discovery.field.StateField` or a trained model with
``state_gaussians(state_id)`` (see :func:`~pd2gs.discovery.field.as_state_field`).
"""
from __future__ import annotations

import logging
import time
import traceback
from typing import Any

import cv2
import numpy as np
import torch

import pd2gs
from rsart.camera import Camera

from . import motion
from .config import DiscoveryConfig
from .counter import count_by_trajectories, count_rigid_motions, local_rigid_motions, sample_image_pairs, vlm_count
from .field import StateField, as_state_field
from .kinematics import estimate_joint
from .masks import make_provider, sample_prompts, visibility_sets
from .meshing import clean_mesh, render_depth, tsdf_fuse
from .refine import boundary_split
from .submission import ObjectFailure, ObjectResult, PartResult

log = logging.getLogger(__name__)


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
def count_parts(fld: StateField, dyn: np.ndarray, obj, states: list[str], cfg: DiscoveryConfig) -> tuple[int, dict]:
    """Number of movable parts by ``cfg.counter`` -> (n, diagnostics)."""
    if cfg.counter == "given":
        n = cfg.given_count if cfg.given_count is not None else len(obj.meta.parts) - 1
        return int(n), {"counter": "given"}
    if cfg.counter == "vlm":
        pairs = sample_image_pairs(obj, states, cfg.vlm.n_pairs, cfg.vlm.seed)
        n, answers = vlm_count(pairs, cfg.vlm.url, cfg.vlm.model, cfg.vlm.api_key_env, cfg.vlm.timeout_s)
        return n, {"counter": "vlm", "answers": answers}
    if cfg.counter == "trajectory":
        sel = dyn & (np.asarray(fld.opacities).reshape(-1) >= cfg.count_min_opacity)
        if sel.sum() < 10:
            sel = dyn
        if sel.sum() == 0:
            return 0, {"counter": "trajectory", "n_voters": 0}
        n, diag = count_by_trajectories(local_rigid_motions(fld.means[:, sel], seed=cfg.seed), cfg.max_parts,
                                        cfg.min_silhouette, cfg.seed)
        return n, {"counter": "trajectory", "n_voters": int(sel.sum()), **diag}
    md = fld.means[:, dyn]
    if md.shape[1] < 3:
        return 0, {"counter": "motion", "support": []}
    dmax = float(motion.max_displacement(md).max())
    mc = count_rigid_motions(md, cfg.ransac_thresh_rel * dmax, cfg.min_part_frac, cfg.max_parts,
                             cfg.ransac_iters, cfg.seed)
    return mc.n, {"counter": "motion", "support": mc.support}


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


def articulate_joints(fld: StateField, labels: np.ndarray, joints: dict, obj, cfg: DiscoveryConfig
                      ) -> tuple[dict, np.ndarray, dict]:
    """Photometric refinement of the centre-based joints (:mod:`.articulate`) on each state's train views."""
    from .articulate import FitSettings, fit_articulation

    views = [[(cam, _resize(view.rgb, cam)) for _, cam, view in
              pick_views(obj, s, cfg.articulate_views, cfg.articulate_max_side)] for s in fld.state_ids]
    ev = obj.meta.eval_states
    settings = FitSettings(iters=cfg.articulate_iters, relabel=cfg.relabel, chain=cfg.chain, absorb=cfg.absorb,
                           absorb_margin=cfg.absorb_margin, part_ref=cfg.part_ref)
    return fit_articulation(fld, labels, joints, views, ev[cfg.articulate_ref], ev["end"], settings, cfg.background,
                            cfg.render_backend, cfg.seed, start=ev["start"])


# ----------------------------------------------------------------------------- the pipeline
def discover(field_or_model: Any, obj, config: DiscoveryConfig | None = None) -> ObjectResult:
    """Parts, joints and meshes of one object (an ``rsart.load`` RSArtObject) from its trained field."""
    cfg = config or DiscoveryConfig()
    t0 = time.perf_counter()
    ev = obj.meta.eval_states
    all_states = getattr(field_or_model, "state_ids", None)  # a StateField, or a model that lists its states
    if all_states is None:                                   # else: the multi-part states (the paper trains on them)
        all_states = [s.id for s in obj.meta.states if s.kind == "multi"]
    states = used_states(obj, list(all_states), cfg.n_states)
    for s in (ev["start"], ev["end"]):
        if s not in states:
            raise ObjectFailure(f"the field has no {s!r} state (eval_states needs it; field states: {list(all_states)})")
    fld = as_state_field(field_or_model, states)
    diag: dict[str, Any] = {"states": states, "n_gaussians": fld.n}
    dyn = motion.dynamic_mask(fld.means, cfg.tau_mot)
    diag["n_dynamic"] = int(dyn.sum())
    n_parts, cdiag = count_parts(fld, dyn, obj, states, cfg)
    diag["count"] = {"n": n_parts, **cdiag}
    if n_parts < 1 or not dyn.any():
        raise ObjectFailure(f"no movable part found ({int(dyn.sum())} dynamic Gaussians, count {n_parts})")
    labels = motion.coarse_labels(fld.means, n_parts, cfg.tau_mot, cfg.min_cluster_frac, cfg.kmeans_seed,
                                  cfg.kmeans_n_init, cfg.cluster)
    if cfg.split_disconnected:
        labels = motion.split_disconnected(fld.means[fld.index(ev["start"])], labels,
                                           max(3, int(cfg.min_cluster_frac * max(1, int(dyn.sum())))))
        diag["count"]["after_spatial_split"] = int(labels.max())
    diag["coarse_sizes"] = np.bincount(labels).tolist()
    if cfg.refine:
        fld, labels, diag["refine"] = refine_parts(fld, labels, obj, states, ev["start"], cfg)
    fld.labels = labels
    joints = {}
    for p in range(1, int(labels.max()) + 1):
        sel = labels == p
        if sel.sum() >= 3:
            joints[p] = estimate_joint(fld.means[:, sel], fld.state_ids, ev["start"], ev["end"], cfg.joint_rule,
                                       cfg.paper_r_thresh, cfg.bic_noise_rel, cfg.robust_thresh_rel,
                                       cfg.robust_iters, cfg.seed)
    if cfg.articulate and joints:
        joints, labels, diag["articulate"] = articulate_joints(fld, labels, joints, obj, cfg)
        joints = {p: j for p, j in joints.items() if (labels == p).sum() >= 3}
        fld.labels = labels
    ref_means = fld.means[fld.index(ev["start"])]
    extent = float(np.linalg.norm(np.ptp(ref_means, axis=0)))
    voxel = cfg.voxel_size or extent / 128
    mesh_states = [ev.get(s, s) for s in cfg.mesh_states.split(",")]
    meshes = {sid: part_meshes(fld, labels, obj, sid, cfg, voxel) for sid in mesh_states}
    parts = [PartResult("static", 0, {sid: meshes[sid][0].get(0) for sid in mesh_states})]
    parts += [PartResult(f"p{p}", p, {sid: meshes[sid][0].get(p) for sid in mesh_states}, j)
              for p, j in joints.items()]
    diag["seconds"] = time.perf_counter() - t0
    diag["joints"] = {p.name: {"type": p.joint.type, "type_paper": p.joint.type_paper, "type_bic": p.joint.type_bic,
                               **p.joint.diagnostics} for p in parts if p.joint is not None}
    return ObjectResult(obj.meta.object_id, parts, {sid: meshes[sid][1] for sid in mesh_states}, diag, fld)


def discover_safe(field_or_model: Any, obj, config: DiscoveryConfig | None = None) -> ObjectResult | ObjectFailure:
    """:func:`discover` that returns an ObjectFailure (reason + traceback logged) instead of raising."""
    try:
        return discover(field_or_model, obj, config)
    except Exception as e:  # a failed object becomes null in the submission, never a crash
        log.error("%s: discovery failed: %s\n%s", getattr(obj, "id", "?"), e, traceback.format_exc())
        return e if isinstance(e, ObjectFailure) else ObjectFailure(f"{type(e).__name__}: {e}")


def method_block(cfg: DiscoveryConfig, states_used: int | None = None) -> dict:
    """The submission's ``method`` object for these settings (ablation flags included)."""
    return {"name": "PD2GS", "version": pd2gs.__version__, "inputs": ["rgb"], "camera_poses": "gt",
            "states_used": states_used if states_used is not None else (cfg.n_states or "all"),
            "discovery": {"counter": cfg.counter, "refine": cfg.refine, "articulate": cfg.articulate,
                          "relabel": cfg.relabel, "mask_provider": cfg.mask_provider,
                          "joint_rule": cfg.joint_rule, "n_states": cfg.n_states}}


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
