"""Benchmark (diagnostic): where PD²GS discovery's gap lies, by the articulated fit from five starts.

On each object's stored stage-1 field (a ``pd2gs_suite.py`` work folder: ``WORK/data`` and
``WORK/runs/<object_id>``) the discovery's articulated fit (its default settings, ``--iters`` steps) runs
from five starts that differ only in who owns each Gaussian and in the joints:

* ``kabsch``: discovery's own start (stage 1's rigid-motion clusters, their Kabsch joints, a flat tree);
* ``search``: discovery's other start, the ``kabsch`` start after the coarse joint search
  (:func:`pd2gs.discovery.pipeline.search`; where the search keeps nothing it is the ``kabsch`` start again);
* ``true-ownership``: each Gaussian given its true part, the Kabsch joints re-estimated on those clusters
  (flat tree): a perfect segmentation, joints as discovery would estimate them;
* ``true-joints``: discovery's ownership, each body given the true joint of the part most of its Gaussians
  belong to (flat tree, so a chain's child gets its own joint, not its world motion);
* ``truth``: true ownership, true joints and the true tree.

Each start is scored, before and after the fit, by the held-out loss model selection uses
(:func:`pd2gs.articulated.fit.evaluate_views`: render L1 + the fit's silhouette weight x |alpha - mask|
on every held-out view). Where ``truth`` ends lowest the objective prefers the truth and the miss is the
optimisation; ``true-ownership`` against ``true-joints`` says which half of the start it cannot recover.
A Gaussian's true part is the one whose posed surface (canonical state) is nearest its canonical centre.

    python benchmarks/pd2gs_oracle_gap.py --work /work/suite-t --objects woven_basket-0000,stand-0000

Writes ``benchmarks/results/pd2gs-oracle-gap.md`` and ``.json`` (override with ``--out``). Uses the
ground truth (meta.json and the twin), so it is a diagnostic of the method, never a part of it.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

ARMS = ("kabsch", "search", "true-ownership", "true-joints", "truth")

Joint = tuple  # (type, unit axis (3,), pivot (3,), values (S,)), canonical frame, values relative to the reference


def true_labels(twin, ref_values: dict, means: np.ndarray, samples: int = 60000, seed: int = 0) -> np.ndarray:
    """(N,) index of the twin part whose surface, posed at ``ref_values``, is nearest each point of
    ``means`` (N, 3) (metres, world frame at that configuration); ``samples`` area samples per part."""
    from scipy.spatial import cKDTree

    best = np.full(len(means), np.inf)
    lab = np.zeros(len(means), dtype=np.int64)
    rng = np.random.default_rng(seed)
    for p, mesh in enumerate(twin.posed_meshes(ref_values)):
        pts = mesh.sample(samples, seed=int(rng.integers(1 << 31)))
        dist, _ = cKDTree(pts).query(means)
        lab = np.where(dist < best, p, lab)
        best = np.minimum(dist, best)
    return lab


def true_joints(twin, state_values: list[dict], ref: int) -> dict[int, Joint]:
    """Part index -> its joint in the articulated model's convention: axis and pivot in the canonical frame
    (the world at state ``ref``: :meth:`rsart.kinematics.Twin.posed_axes`, so a child's joint is carried
    by its parent's pose there) and one value per state of ``state_values`` (joint name -> rad | m), relative
    to state ``ref``. Posing a model built from these with the twin's tree gives the twin's part motions
    from the reference state (checked in tests/benchmarks/test_pd2gs_oracle_gap.py)."""
    axes = twin.posed_axes(state_values[ref])
    out = {}
    for j in twin.joints:
        origin, axis = axes[j.name]
        vals = np.array([sv[j.name] - state_values[ref][j.name] for sv in state_values], dtype=np.float64)
        out[j.child] = (j.type, axis / np.linalg.norm(axis), np.asarray(origin, dtype=np.float64), vals)
    return out


def build_model(gaussians, ownership: np.ndarray, parent: list[int], joints: list[Joint]):
    """An ArticulatedGaussians with a copy of ``gaussians``, bodies 1..K with ``parent`` and ``joints``."""
    import torch

    from pd2gs.articulated.model import ArticulatedGaussians

    K = len(joints)
    S = len(joints[0][3]) if joints else 1
    return ArticulatedGaussians(copy.deepcopy(gaussians), parent, [j[0] for j in joints],
                                np.array([j[1] for j in joints]).reshape(K, 3),
                                np.array([j[2] for j in joints]).reshape(K, 3),
                                np.stack([np.asarray(j[3], dtype=np.float64) for j in joints], axis=1).reshape(S, K),
                                torch.as_tensor(ownership))


def starts(d, twin) -> tuple[dict, np.ndarray, dict[int, Joint]]:
    """The starts of the module doc but ``search`` from an initialised Discovery ``d`` -> (arm -> model, the true
    labels of the model's Gaussians, part -> true joint)."""
    import torch

    from pd2gs.kinematics import estimate_joint

    k0 = d.model
    meta = d.obj.meta
    ref = d.states[d.ref_index]
    svals = [meta.state(s).values for s in d.states]
    gt = true_labels(twin, svals[d.ref_index], k0.gaussians.means.detach().numpy())
    truth = true_joints(twin, svals, d.ref_index)
    parts = sorted(truth)
    if parts != list(range(1, len(parts) + 1)):
        raise ValueError(f"{d.obj.id}: parts {parts} are not numbered 1..{len(parts)}")
    parent_of = {j.child: j.parent for j in twin.joints}
    if any(parent_of[p] >= p for p in parts):
        raise ValueError(f"{d.obj.id}: a part is listed before its parent")
    out = {"kabsch": copy.deepcopy(k0)}
    other = d.end if ref != d.end else d.start
    est = []
    for p in parts:
        sel = gt == p
        if sel.sum() < 3:
            raise ValueError(f"{d.obj.id}: part {p} owns {int(sel.sum())} Gaussians of the field")
        jf = estimate_joint(d.stage1_means[:, sel], d.states, ref, other, "bic", seed=d.cfg.kmeans_seed)
        est.append((jf.type, np.asarray(jf.axis), np.asarray(jf.origin), np.array([jf.values[s] for s in d.states])))
    out["true-ownership"] = build_model(k0.gaussians, gt, [-1] + [0] * len(parts), est)
    m = copy.deepcopy(k0)
    lab = m.labels().numpy()
    for b in range(1, m.num_bodies):
        p = int(np.bincount(gt[lab == b], minlength=len(parts) + 1)[1:].argmax()) + 1
        t, axis, pivot, vals = truth[p]
        m.joint_types[b - 1] = t
        m.axes.data[b - 1] = torch.as_tensor(axis, dtype=m.axes.dtype)
        m.pivots.data[b - 1] = torch.as_tensor(pivot, dtype=m.axes.dtype)
        m.values.data[:, b - 1] = torch.as_tensor(vals, dtype=m.values.dtype)
    out["true-joints"] = m
    out["truth"] = build_model(k0.gaussians, gt, [-1] + [parent_of[p] for p in parts], [truth[p] for p in parts])
    return out, gt, truth


def body_errors(model, gt: np.ndarray, truth: dict[int, Joint]) -> list[dict]:
    """Per movable body: the true part most of its Gaussians belong to, its share of them, the body's
    axis error to that part's joint (degrees, sign-free), its worst value error over the states
    (degrees or cm; the sign follows the axis), or a type mismatch, and for a hinge matched to a hinge its
    line error: the distance (cm) of the body's pivot from the true hinge line, normal to the true axis."""
    from rsart.metrics.joints import axis_angle_deg

    lab = model.labels().numpy()
    rows = []
    for b in range(1, model.num_bodies):
        own = gt[lab == b]
        if len(own) == 0:
            rows.append({"body": b, "part": None, "n": 0})
            continue
        p = int(np.bincount(own, minlength=len(truth) + 1).argmax())
        j = model.joint_dict(b)
        row = {"body": b, "parent": int(j["parent"]), "type": j["type"], "part": p, "n": int(len(own)),
               "purity": float((own == p).mean())}
        if p in truth:
            t, axis, _, vals = truth[p]
            a = np.asarray(j["axis"], dtype=np.float64)
            a = a / np.linalg.norm(a)
            c = float(a @ axis)
            row["axis_err_deg"] = axis_angle_deg(a, axis)
            if j["type"] == t:
                err = np.abs(np.sign(c or 1.0) * np.asarray(j["values"]) - vals).max()
                row["value_err"] = float(np.degrees(err) if t == "revolute" else 100 * err)
            if j["type"] == t == "revolute":  # not the scorer's line_distance: skew lines can cross far from the part
                q = np.asarray(j["pivot"], dtype=np.float64) - truth[p][2]
                row["line_err_cm"] = float(100 * np.linalg.norm(q - (q @ axis) * axis))
        rows.append(row)
    return rows


def run_object(work: str, oid: str, arms: list[str], iters: int, threads: int = 1) -> dict:
    """The starts ``arms`` of one object, each fitted ``iters`` steps -> its record."""
    import torch

    import rsart
    from pd2gs.articulated.fit import evaluate_views, fit_articulated
    from pd2gs.discovery import pipeline as P
    from pd2gs.discovery.config import DiscoveryConfig
    from pd2gs.runner import set_threads
    from pd2gs.train import TrainedModel, load_field
    from rsart.twin_io import read_twin

    set_threads(threads)
    t0 = time.time()
    obj = rsart.load(Path(work) / "data")[oid]
    tcfg, fld = load_field(Path(work) / "runs" / oid)
    trained = TrainedModel(fld, tcfg.states, tcfg.background)
    d = P.stage1(trained, obj, dataclasses.replace(DiscoveryConfig(), background=trained.background))
    d.frames, d.masks = P.training_views(d.obj, d.states, d.cfg)
    P.initialise(d)
    models, gt, truth = starts(d, read_twin(Path(work) / "data" / oid))
    fc = P.fit_config(d, iters)

    def held(m) -> float:
        return evaluate_views(m, d.frames, "test", fc.background, fc.backend, d.masks, fc.silhouette)

    rec = {"object_id": oid, "category": obj.meta.category, "states": d.states,
           "canonical": d.states[d.ref_index], "n_gaussians": int(len(gt)),
           "true_sizes": np.bincount(gt).tolist(), "arms": {}}
    if "search" in arms:  # from the start as initialised, before any arm's fit changes the kabsch model
        d.model = copy.deepcopy(models["kabsch"])
        P.search(d)
        models["search"] = d.model
        rec["search_kept"] = bool(d.diag["search"]["kept"])
    for name in arms:
        m = models[name]
        before = held(m)
        bodies_start = body_errors(m, gt, truth)
        t1 = time.time()
        torch.manual_seed(0)
        fit_articulated(m, d.frames, d.masks, fc)
        rec["arms"][name] = {"held_out_start": before, "held_out": held(m), "fit_s": time.time() - t1,
                             "bodies_start": bodies_start, "bodies": body_errors(m, gt, truth)}
    rec["seconds"] = time.time() - t0
    return rec


def _cell(v: float, best: float) -> str:
    return f"**{v:.5f}**" if v == best else f"{v:.5f}"


def _bodies(rows: list[dict]) -> str:
    out = []
    for r in rows:
        if r.get("part") is None:
            out.append(f"b{r['body']}: empty")
            continue
        s = f"b{r['body']}→p{r['part']} {r['type'][:3]} {100 * r['purity']:.0f} %"
        if "axis_err_deg" in r:
            s += f", axis {r['axis_err_deg']:.1f}°"
        if "value_err" in r:
            s += f", value ≤ {r['value_err']:.1f}{'°' if r['type'] == 'revolute' else ' cm'}"
        if "line_err_cm" in r:
            s += f", line {r['line_err_cm']:.1f} cm"
        out.append(s)
    return "; ".join(out)


def report(recs: list[dict], arms: list[str], iters: int, header: str) -> str:
    lines = [header, "", "## Held-out loss after the fit (lowest in bold; start's in brackets)", "",
             "| object | canonical | " + " | ".join(arms) + " |", "|---|---|" + "---:|" * len(arms)]
    for r in recs:
        best = min(r["arms"][a]["held_out"] for a in arms)
        lines.append(f"| {r['object_id']} | {r['canonical']} | " + " | ".join(
            f"{_cell(r['arms'][a]['held_out'], best)} ({r['arms'][a]['held_out_start']:.5f})" for a in arms) + " |")
    lines += ["", f"## Bodies after the fit ({iters} steps): true part, purity, axis, worst value and hinge-line errors", ""]
    for r in recs:
        lines.append(f"- **{r['object_id']}** (true sizes {r['true_sizes']}):")
        for a in arms:
            if a == "kabsch" and "bodies_start" in r["arms"][a]:
                lines.append(f"  - kabsch, before the fit: {_bodies(r['arms'][a]['bodies_start'])}")
            kept = "" if a != "search" or r.get("search_kept", True) else " (kept nothing: the kabsch start)"
            lines.append(f"  - {a}{kept}: {_bodies(r['arms'][a]['bodies'])}")
    return "\n".join(lines) + "\n"


def main() -> int:
    from common import cpu_description, load_avg, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True, help="a pd2gs_suite.py work folder (data/, runs/)")
    ap.add_argument("--objects", required=True, help="comma-separated object ids with a trained field in WORK/runs")
    ap.add_argument("--arms", default=",".join(ARMS), help="comma list of " + ", ".join(ARMS))
    ap.add_argument("--iters", type=int, default=600, help="fit steps (default 600, discovery's main fit)")
    ap.add_argument("--workers", type=int, default=1, help="objects at once (one thread each)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "pd2gs-oracle-gap.md")
    args = ap.parse_args()
    arms = [a for a in args.arms.split(",") if a]
    bad = [a for a in arms if a not in ARMS]
    if bad:
        raise SystemExit(f"unknown arms {bad}; choose from {list(ARMS)}")
    ids = [o for o in args.objects.split(",") if o]
    missing = [o for o in ids if not (args.work / "runs" / o / "metrics.json").is_file()]
    if missing:
        raise SystemExit(f"no finished training run under {args.work / 'runs'} for {missing}")
    t0 = time.time()
    threads = 1 if args.workers > 1 else max(1, os.cpu_count() or 1)
    with ProcessPoolExecutor(args.workers) as pool:
        recs = list(pool.map(run_object, [str(args.work)] * len(ids), ids, [arms] * len(ids),
                             [args.iters] * len(ids), [threads] * len(ids)))
    import subprocess

    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    header = ("# PD²GS: the articulated fit from discovery's start and from the truth\n\n"
              f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {cpu_description()}, at commit "
              f"{commit}, {args.workers} object(s) at once, one thread each; load average at the end "
              f"{', '.join(f'{x:.1f}' for x in load_avg())}; {(time.time() - t0) / 60:.0f} min. Accuracy only "
              "(no timing target). Command: `python benchmarks/pd2gs_oracle_gap.py --work "
              f"{args.work} --objects {args.objects} --iters {args.iters} --workers {args.workers}`. Starts: "
              "benchmarks/pd2gs_oracle_gap.py's module doc.")
    md = report(recs, arms, args.iters, header)
    write_report(args.out, md, {"objects": ids, "arms": arms, "iters": args.iters, "records": recs})
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
