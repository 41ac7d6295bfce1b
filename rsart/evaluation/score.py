"""Scoring a validated submission against the ground truth, one object at a time (in parallel).

Per object (docs/evaluation.md has every formula):

1. true joints at the ``start`` state (axis/origin moved with their parent), Δv = value[end] − value[start];
2. Hungarian matching of predicted to true movable parts (:func:`rsart.metrics.match_parts`);
3. per true movable part: Axis Ang, Axis Pos (revolute), Part Motion, joint-type accuracy, CD-m per state;
   unmatched true parts fail every metric;
4. CD-s (static part vs true part 0) and CD-w (whole, or union of the predicted parts) per state;
5. movable-part-count accuracy; PSNR/SSIM and part-mask scores when renders/masks were submitted.

Results are typed records (:class:`ObjectScore` holding one :class:`PartScore` per true movable part)
whose ``to_dict()`` is the JSON-ready dict that scores.json and :mod:`rsart.evaluation.report` read;
:func:`score_submission` returns those dicts, :func:`score_records` the records. A metric is either a
finite number in ``metrics``, or listed in ``failures`` with its reason, or in ``not_applicable`` (Axis
Pos of prismatic joints, image metrics of a submission without images). Seeds derive from names, so any
worker count gives identical numbers.
"""
from __future__ import annotations

import hashlib
import json
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ..errors import Problem, RsartError
from ..format import ObjectMeta, read_meta
from ..io import read_mask_png, read_png_rgb, resolve_inside
from ..metrics.chamfer import ChamferConfig, chamfer_floor, chamfer_mesh, mesh_area, prepare_prediction
from ..metrics.images import mask_scores, psnr, ssim
from ..metrics.joints import JointEstimate, joint_errors
from ..metrics.matching import match_parts
from ..twin_io import read_twin
from .ground_truth import GroundTruth, resolve_states
from .submission import Limits, MeshError, PredObject, Submission, load_mesh

SCORES_FORMAT = "rsart-scores/1"
PART_METRICS = ("cd_m_start", "cd_m_end", "cd_m", "axis_ang", "axis_pos", "part_motion", "type_acc")
OBJECT_METRICS = ("cd_s_start", "cd_s_end", "cd_s", "cd_m_start", "cd_m_end", "cd_m", "cd_w_start", "cd_w_end",
                  "cd_w", "axis_ang", "axis_pos", "part_motion_rev", "part_motion_pri", "type_acc", "count_acc",
                  "psnr", "ssim", "mask_iou", "mask_acc", "mask_f1")
IMAGE_METRICS = ("psnr", "ssim", "mask_iou", "mask_acc", "mask_f1")


@dataclass(frozen=True)
class EvalConfig:
    """Everything that changes a score; hashed into scores.json (``config_hash``)."""

    chamfer: ChamferConfig = field(default_factory=ChamferConfig)
    states: str = "start,end"
    limits: Limits = field(default_factory=Limits)

    def to_dict(self) -> dict:
        return {"chamfer": self.chamfer.to_dict(), "states": self.states,
                "matching": "hungarian: axis_ang + 10*line_distance(revolute) + part_motion, type-consistent first",
                "joint_frame": "world frame at eval_states.start",
                "pred_whole_default": "union of the component-filtered predicted parts",
                "limits": {"max_mesh_bytes": self.limits.max_mesh_bytes,
                           "max_total_bytes": self.limits.max_total_bytes}}

    def hash(self) -> str:
        """SHA-256 of the canonical JSON of :meth:`to_dict`."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode("utf-8")).hexdigest()


@dataclass
class _Task:
    object_id: str
    folder: Path
    pred: PredObject | None
    cfg: EvalConfig


class _Invalid(Exception):
    def __init__(self, problems: list[Problem]):
        self.problems = problems


# ----------------------------------------------------------------------------- records
@dataclass(kw_only=True)
class Scores:
    """Every metric is exactly one of: a finite number in ``metrics``, a reason in ``failures``, or named in
    ``not_applicable``. ``chamfer_by_state``: ``"<metric>@<state id>"`` -> Chamfer value, once any is set."""

    metrics: dict[str, float] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)
    not_applicable: list[str] = field(default_factory=list)
    chamfer_by_state: dict[str, float] | None = None

    def put(self, key: str, value: float | None, reason: str | None) -> None:
        """``value`` as metric ``key``, or the failure ``reason`` when there is no value."""
        if value is not None:
            self.metrics[key] = float(value)
        else:
            self.failures[key] = reason or "failed"

    def per_state(self, base: str, sid: str, v: float | None, why: str | None) -> None:
        """One state's Chamfer value ``base@sid``, or its failure."""
        if v is not None:
            self.by_state()[f"{base}@{sid}"] = v
        else:
            self.failures[f"{base}@{sid}"] = why

    def by_state(self) -> dict[str, float]:
        if self.chamfer_by_state is None:
            self.chamfer_by_state = {}
        return self.chamfer_by_state

    def state_means(self, base: str, states: list[str], start: str, end: str) -> None:
        """From per-state values ``base@sid`` derive ``base_start``, ``base_end`` and ``base`` (mean of the states)."""
        per = self.by_state()
        vals = [per.get(f"{base}@{s}") for s in states]
        for alias, sid in (("start", start), ("end", end)):
            if sid in states:
                v = per.get(f"{base}@{sid}")
                self.put(f"{base}_{alias}", v, self.failures.get(f"{base}@{sid}"))
        if all(v is not None for v in vals):
            self.metrics[base] = _mean(vals)
        else:
            bad = [s for s, v in zip(states, vals) if v is None]
            self.failures[base] = f"no value in state(s) {', '.join(bad)}"

    def drop_state_failures(self) -> None:
        """Forget the per-state failures once the state means have named them."""
        for k in [k for k in self.failures if "@" in k]:
            del self.failures[k]

    def _scores_dict(self) -> dict:
        return {"metrics": self.metrics, "failures": self.failures, "not_applicable": self.not_applicable}


@dataclass(kw_only=True)
class PartScore(Scores):
    """The scores of one true movable part (``part`` its index in meta.json) and the predicted part matched to it."""

    movable_index: int
    part: int
    name: str
    joint: str
    type: str
    pred: str | None
    pred_type: str | None

    def to_dict(self) -> dict:
        d = {"movable_index": self.movable_index, "part": self.part, "name": self.name, "joint": self.joint,
             "type": self.type, "pred": self.pred, "pred_type": self.pred_type, **self._scores_dict()}
        if self.chamfer_by_state is not None:
            d["chamfer_by_state"] = self.chamfer_by_state
        return d


@dataclass(kw_only=True)
class ObjectScore(Scores):
    """The scores of one object: ``status`` "scored" or "failed" (with ``reason``), its parts, and the
    object-level metrics (means over parts, static/whole Chamfer, counts, images)."""

    object_id: str
    category: str
    units: str
    eval_states: dict[str, str]
    chamfer_states: list[str]
    n_true_movable: int
    parts: list[PartScore] = field(default_factory=list)
    bbox_diag: float | None = None
    """diagonal of the true object's box over the start and end states (scene size for report.py's caps)."""
    chamfer_floor: dict[str, dict[str, float]] = field(default_factory=dict)
    status: str = "scored"
    reason: str | None = None
    n_pred_movable: int | None = None
    unmatched_pred: list[str] | None = None
    part_failures: dict[str, int] | None = None
    image_failures: list[str] | None = None

    def to_dict(self) -> dict:
        """The JSON-ready dict of scores.json (the shape :mod:`rsart.evaluation.report` reads)."""
        d = {"object_id": self.object_id, "category": self.category, "units": self.units,
             "eval_states": self.eval_states, "chamfer_states": self.chamfer_states,
             "n_true_movable": self.n_true_movable, **self._scores_dict(), "parts": [p.to_dict() for p in self.parts]}
        if self.bbox_diag is not None:
            d["bbox_diag"] = self.bbox_diag
        d.update(chamfer_floor=self.chamfer_floor, status=self.status)
        if self.reason is not None:
            d["reason"] = self.reason
        if self.n_pred_movable is not None:
            d["n_pred_movable"] = self.n_pred_movable
            d["unmatched_pred"] = self.unmatched_pred
        if self.chamfer_by_state is not None:
            d["chamfer_by_state"] = self.chamfer_by_state
        if self.part_failures is not None:
            d["part_failures"] = self.part_failures
        if self.image_failures:
            d["image_failures"] = self.image_failures
        return d


# ----------------------------------------------------------------------------- helpers
def _mean(xs: list[float]) -> float:
    return float(np.mean(xs))


def _true_joints(meta: ObjectMeta, twin, start: str, end: str) -> list[tuple[int, JointEstimate, Any]]:
    """(part index, JointEstimate at the start state, Joint) for every movable part, by part index."""
    vs, ve = meta.state(start).values, meta.state(end).values
    axes = twin.posed_axes(vs)
    out = []
    for p in range(1, len(meta.parts)):
        j = twin.joint_of_part(p)
        o, a = axes[j.name]
        out.append((p, JointEstimate.make(j.type, a, o, ve[j.name] - vs[j.name]), j))
    return out


def _load_pred_meshes(pred: PredObject, states: list[str], cfg: EvalConfig
                      ) -> tuple[dict[tuple[str, str], trimesh.Trimesh], dict[str, trimesh.Trimesh]]:
    """Parse (and component-filter) every predicted mesh needed; raise _Invalid listing unusable files."""
    problems: list[Problem] = []
    parts: dict[tuple[str, str], trimesh.Trimesh] = {}
    whole: dict[str, trimesh.Trimesh] = {}

    def load(jpath: str, path: Path, used: bool = True):
        try:
            m = load_mesh(path, cfg.limits.max_mesh_bytes)  # every mesh is parsed (validated), used or not
            return prepare_prediction(m, cfg.chamfer) if used else None
        except MeshError as e:
            problems.append(Problem(jpath, f"{path.name}: {e}"))
        except OSError as e:
            problems.append(Problem(jpath, f"{path.name}: cannot be read ({e.strerror})"))
        return None

    for part in pred.parts:
        for sid, path in part.meshes.items():
            m = load(f"{part.json_path}.meshes.{sid}", path, sid in states)
            if m is not None:
                parts[(part.name, sid)] = m
    for sid, path in pred.whole.items():
        m = load(f"results.{pred.object_id}.whole.{sid}", path, sid in states)
        if m is not None:
            whole[sid] = m
    if problems:
        raise _Invalid(problems)
    return parts, whole


def _cd(pred_m, gt_m, cfg: EvalConfig, key: tuple) -> tuple[float | None, str | None]:
    if pred_m is None:
        return None, "no predicted mesh for this state"
    try:
        return chamfer_mesh(pred_m, gt_m, cfg.chamfer, key=key, filter_pred=False), None
    except ValueError as e:
        return None, str(e)


# ----------------------------------------------------------------------------- one object
def score_object(task: _Task) -> dict:
    """Score one object; returns a JSON-ready result dict, or {"problems": [...]} for unusable mesh files."""
    out = score_object_record(task)
    return out.to_dict() if isinstance(out, ObjectScore) else out


def score_object_record(task: _Task) -> ObjectScore | dict:
    """Score one object: its :class:`ObjectScore`, or {"problems": [...]} for unusable mesh files."""
    try:
        return _score_object(task)
    except _Invalid as e:
        return {"object_id": task.object_id, "problems": [[p.path, p.message] for p in e.problems]}


def _score_object(task: _Task) -> ObjectScore:
    cfg = task.cfg
    meta = read_meta(task.folder)
    start, end = meta.eval_states["start"], meta.eval_states["end"]
    states = resolve_states(meta, cfg.states)
    res = ObjectScore(object_id=meta.object_id, category=meta.category, units=meta.units,
                      eval_states={"start": start, "end": end}, chamfer_states=states,
                      n_true_movable=len(meta.parts) - 1)
    pred = task.pred
    pred_meshes, pred_whole = _load_pred_meshes(pred, states, cfg) if pred is not None else ({}, {})
    twin = read_twin(task.folder, meta, visuals=False)
    true = _true_joints(meta, twin, start, end)
    gt_posed = {sid: twin.posed_meshes(meta.state(sid).values) for sid in states}
    box = np.concatenate([twin.bounds(meta.state(s).values) for s in (start, end)])
    res.bbox_diag = float(np.linalg.norm(box.max(0) - box.min(0)))  # scene size for the penalty caps (report.py)
    res.chamfer_floor = {sid: {"static": chamfer_floor(mesh_area(gt_posed[sid][0]), cfg.chamfer.n_samples),
                                  "whole": chamfer_floor(sum(mesh_area(m) for m in gt_posed[sid]),
                                                         cfg.chamfer.n_samples)} for sid in states}

    if pred is None:
        res.status = "failed"
        res.reason = "no result (null in the submission)"
        for p, tj, j in true:
            res.parts.append(_part_record(meta, p, tj, j, None, None))
            for k in PART_METRICS:
                if k == "axis_pos" and tj.type != "revolute":
                    res.parts[-1].not_applicable.append(k)
                else:
                    res.parts[-1].failures[k] = res.reason
        types = {tj.type for _, tj, _ in true}
        for k in OBJECT_METRICS:
            applicable = not (k in IMAGE_METRICS or (k in ("axis_pos", "part_motion_rev") and "revolute" not in types)
                              or (k == "part_motion_pri" and "prismatic" not in types))
            if applicable:
                res.failures[k] = res.reason
            else:
                res.not_applicable.append(k)
        return res

    res.status = "scored"
    movable = pred.movable
    res.n_pred_movable = len(movable)
    pred_j = [JointEstimate.make(pp.joint.type, pp.joint.axis, pp.joint.origin,
                                 pp.joint.values[end] - pp.joint.values[start]) for pp in movable]
    match = match_parts(pred_j, [tj for _, tj, _ in true])
    res.unmatched_pred = [movable[i].name for i in match.unmatched_pred]

    # ---- movable parts
    for ti, (p, tj, j) in enumerate(true):
        pi = match.pred_for_true(ti)
        rec = _part_record(meta, p, tj, j, movable[pi].name if pi is not None else None,
                           movable[pi].joint.type if pi is not None else None)
        res.parts.append(rec)
        if pi is None:
            reason = "no predicted part matched to this part (fewer predicted movable parts)"
            for k in PART_METRICS:
                if k == "axis_pos" and tj.type != "revolute":
                    rec.not_applicable.append(k)
                else:
                    rec.failures[k] = reason
            continue
        e = joint_errors(pred_j[pi], tj)
        for k in ("axis_ang", "part_motion"):
            rec.metrics[k] = e[k]
        rec.metrics["type_acc"] = e["type_correct"]
        if e["axis_pos"] is None:
            rec.not_applicable.append("axis_pos")
        else:
            rec.metrics["axis_pos"] = e["axis_pos"]
        for sid in states:
            v, why = _cd(pred_meshes.get((movable[pi].name, sid)), gt_posed[sid][p], cfg,
                         (meta.object_id, "cd-m", meta.parts[p].name, sid))
            rec.by_state()
            rec.per_state("cd_m", sid, v, why)
        rec.state_means("cd_m", states, start, end)
        rec.drop_state_failures()

    # ---- static and whole
    static = pred.parts[0]
    for sid in states:
        v, why = _cd(pred_meshes.get((static.name, sid)), gt_posed[sid][0], cfg, (meta.object_id, "cd-s", sid))
        res.per_state("cd_s", sid, v, why)
        wm, why_w = pred_whole.get(sid), None
        if wm is None:
            ms = [pred_meshes.get((pp.name, sid)) for pp in pred.parts]
            if all(m is not None for m in ms):
                wm = trimesh.util.concatenate(ms) if len(ms) > 1 else ms[0]
            else:
                why_w = "no whole mesh, and not every predicted part has a mesh for this state"
        gt_whole = trimesh.util.concatenate(gt_posed[sid])
        v, why = _cd(wm, gt_whole, cfg, (meta.object_id, "cd-w", sid)) if wm is not None else (None, why_w)
        res.per_state("cd_w", sid, v, why)
    for base in ("cd_s", "cd_w"):
        res.state_means(base, states, start, end)
    res.drop_state_failures()

    # ---- object-level means over movable parts
    _object_means(res, true)
    res.metrics["count_acc"] = 1.0 if len(movable) == len(true) else 0.0
    _score_images(res, task, meta, pred, match, movable)
    return res


def _part_record(meta: ObjectMeta, p: int, tj: JointEstimate, j, pred_name, pred_type) -> PartScore:
    return PartScore(movable_index=p - 1, part=p, name=meta.parts[p].name, joint=j.name, type=tj.type,
                     pred=pred_name, pred_type=pred_type)


def _object_means(res: ObjectScore, true) -> None:
    """Object value of a per-part metric = mean over the parts that scored it; part failures are counted."""
    res.part_failures = {}
    for k in ("cd_m_start", "cd_m_end", "cd_m", "axis_ang", "axis_pos", "type_acc", "part_motion_rev",
              "part_motion_pri"):
        src, want = (k, None)
        if k.startswith("part_motion_"):
            src, want = "part_motion", ("revolute" if k.endswith("rev") else "prismatic")
        parts = [r for r in res.parts if want is None or r.type == want]
        if want is None and k == "axis_pos":
            parts = [r for r in parts if r.type == "revolute"]
        vals = [r.metrics[src] for r in parts if src in r.metrics]
        nfail = sum(1 for r in parts if src in r.failures)
        if vals:
            res.metrics[k] = _mean(vals)
        if nfail:
            res.part_failures[k] = nfail
            if not vals:
                res.failures[k] = f"failed on all {nfail} part(s)"
        if not vals and not nfail:
            res.not_applicable.append(k)


def _score_images(res: ObjectScore, task: _Task, meta: ObjectMeta, pred: PredObject, match, movable) -> None:
    """PSNR/SSIM of submitted renders and part-mask scores of submitted masks, against the dataset's images."""
    if not pred.renders:
        res.not_applicable += ["psnr", "ssim"]
    else:
        ps, ss, bad = [], [], []
        for sid, views in sorted(pred.renders.items()):
            for vid, path in sorted(views.items()):
                try:
                    gt_img = read_png_rgb(resolve_inside(task.folder, f"states/{sid}/rgb/{vid}.png"))
                    img = read_png_rgb(path)
                    ps.append(psnr(img, gt_img))
                    ss.append(ssim(img, gt_img))
                except (RsartError, ValueError) as e:
                    bad.append(f"{sid}/{vid}: {e}")
        _image_result(res, ("psnr", "ssim"), [ps, ss], bad)
    if not pred.masks:
        res.not_applicable += ["mask_iou", "mask_acc", "mask_f1"]
        return
    label_of = {pp.name: i + 1 for i, pp in enumerate(pred.parts)}
    lut = {label_of[pred.parts[0].name]: 1}
    for pi, ti in match.pairs:
        lut[label_of[movable[pi].name]] = ti + 2  # true movable ti is part ti + 1 -> label ti + 2
    iou, acc, f1, bad = [], [], [], []
    for sid, views in sorted(pred.masks.items()):
        for vid, path in sorted(views.items()):
            try:
                gt_m = read_mask_png(resolve_inside(task.folder, f"states/{sid}/mask/{vid}.png"))
                s = mask_scores(read_mask_png(path), gt_m, lut)
                acc.append(s["accuracy"])
                if s["miou"] is not None:
                    iou.append(s["miou"])
                    f1.append(s["mf1"])
            except (RsartError, ValueError) as e:
                bad.append(f"{sid}/{vid}: {e}")
    _image_result(res, ("mask_iou", "mask_acc", "mask_f1"), [iou, acc, f1], bad)


def _image_result(res: ObjectScore, keys: tuple[str, ...], lists: list[list[float]], bad: list[str]) -> None:
    for k, vals in zip(keys, lists):
        if vals:
            res.metrics[k] = _mean(vals)
        else:
            res.failures[k] = "; ".join(bad[:3]) or "no view could be scored"
    if bad:
        res.image_failures = (res.image_failures or []) + bad


# ----------------------------------------------------------------------------- the submission
def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def score_submission(sub: Submission, gt: GroundTruth, cfg: EvalConfig = EvalConfig(),
                     workers: int | None = None) -> tuple[dict[str, dict], list[Problem]]:
    """Score every object of ``gt`` (object id -> result dict, in dataset order) with ``workers`` processes.

    Returns (results, problems); problems are unusable mesh files found while loading (the CLI exits 2).
    The result dicts are :meth:`ObjectScore.to_dict` of :func:`score_records`.
    """
    records, problems = score_records(sub, gt, cfg, workers)
    return {oid: r.to_dict() for oid, r in records.items()}, problems


def score_records(sub: Submission, gt: GroundTruth, cfg: EvalConfig = EvalConfig(),
                  workers: int | None = None) -> tuple[dict[str, ObjectScore], list[Problem]]:
    """:func:`score_submission` as typed records: object id -> :class:`ObjectScore`, and the problems."""
    tasks = [_Task(oid, gt.folder(oid), sub.results.get(oid), cfg) for oid in gt.objects]
    workers = workers or default_workers()
    if workers <= 1 or len(tasks) <= 1:
        outs = [score_object_record(t) for t in tasks]
    else:
        with ProcessPoolExecutor(max_workers=min(workers, len(tasks))) as ex:
            outs = list(ex.map(score_object_record, tasks))
    results, problems = {}, []
    for t, r in zip(tasks, outs):
        if isinstance(r, dict):
            problems += [Problem(p, m) for p, m in r["problems"]]
        else:
            results[t.object_id] = r
    return results, problems
