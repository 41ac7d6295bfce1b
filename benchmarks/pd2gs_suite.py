"""Benchmark: PD²GS on the rsart-synth suite at the default CPU settings, scored by rsart-eval.

For each selected object: render the pd2gs protocol (4 states x 50 train + 10 test views, 320x240,
plain background), train PD²GS (default ``TrainConfig``), discover parts/joints/meshes (default
``DiscoveryConfig``), and -- on the same trained fields, so they cost no extra training -- the
discovery ablations of ``ABLATIONS`` (the paper's pipeline, no silhouette loss, 2 states instead of 4,
the given part count, no model selection, an added depth loss). Each object is one task of pd2gs's runner
(``pd2gs/runner.py``, the one ``pd2gs run`` uses): ``--workers`` at once, in local processes or on Ray
(``--backend ray [--address ADDR]``). Every configuration becomes one rsart-submission/1 that ``rsart-eval`` scores; the report has the paper-style table per category for the default, the wall time per
object, and one row of category means per ablation.

    python benchmarks/pd2gs_suite.py --split two-part [--limit 6] [--work /tmp/pd2gs-suite]
    python benchmarks/pd2gs_suite.py --objects storage-0001,drawer-0000

Writes ``benchmarks/results/pd2gs-rsart-synth.md`` and ``.json`` (override with ``--out``). Re-running
with the same ``--work`` reuses rendered data, finished training runs and finished discoveries; ``--train-only`` stops after
training (e.g. to train a large split while discovery code is still changing).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

TARGETS = {"axis_ang": ("< 1°", lambda v: v < 1), "axis_pos": ("< 0.1", lambda v: v < 0.1),
           "part_motion_rev": ("< 2°", lambda v: v < 2), "part_motion_pri": ("< 0.02", lambda v: v < 0.02),
           "cd_w": ("< 2", lambda v: v < 2), "type_acc": ("≥ 95 %", lambda v: v >= 95),
           "count_acc": ("≥ 90 %", lambda v: v >= 90)}
ROW_METRICS = ("cd_s", "cd_m", "cd_w", "axis_ang", "axis_pos", "part_motion_rev", "part_motion_pri",
               "type_acc", "count_acc")
MINUTES_PER_OBJECT = 8.0
ABLATIONS = {  # name -> DiscoveryConfig overrides (same trained field)
    "default": {},
    "paper": {"mode": "paper"},  # the paper's pipeline: trajectory clusters, refinement, Kabsch joints, its type rule
    "no-silhouette": {"fit_silhouette": 0.0},  # RGB only
    "2-states": {"n_states": 2},  # start and end states only
    "given-count": {"counter": "given"},  # the true part count (meta.json)
    "given-count-seed-1": {"counter": "given", "seed": 1},
    "surface": {"starts": "kabsch,search,surface"},  # + the search on stage 1's rendered surfaces (opt-in)
    "given-surface": {"counter": "given", "starts": "kabsch,search,surface"},
    "no-select": {"select": False},  # the initial count, tree and types
    "search": {"starts": "search"},  # from the coarse joint and ownership search's joints only
    "frozen-ownership": {"fit_ownership": "frozen"},  # each Gaussian keeps its start's (or an edit's) owner in the fits
    "frozen-ownership-seed-1": {"fit_ownership": "frozen", "seed": 1},
    "staged-ownership": {"fit_ownership": "staged"},  # each fit: first half ownership held, second half free
    "staged-ownership-seed-1": {"fit_ownership": "staged", "seed": 1},
    "depth": {"fit_depth": 1.0},  # + an L1 depth loss (its own track: the submission's inputs name depth)
    "fit-80": {"fit_max_side": 80},  # the articulated fit's views at 80 px (the default before 2026-11-26)
    "restarts-2": {"restarts": 2},  # seeds 0 and 1, the lower held-out L1 kept
    "seed-1": {"seed": 1},  # the default with another discovery seed (same trained field): the run-to-run spread
    "fit-80-seed-1": {"fit_max_side": 80, "seed": 1},  # the same at 80 px
    "search-seed-1": {"starts": "search", "seed": 1},
    "kabsch": {"starts": "kabsch"},  # from stage 1's Kabsch joints only (the default until 2026-11-26)
    "kabsch-seed-1": {"starts": "kabsch", "seed": 1},
    "canonical-start": {"canonical": "start"},  # the start state's Gaussians as the canonical geometry (until 2026-11-27)
    # both canonical states discovered, the lower held-out loss kept (twice the discovery where they differ)
    "canonical-both": {"canonical": "widest,start"},
    "canonical-both-seed-1": {"canonical": "widest,start", "seed": 1},
    # selection's finalists (2 per round) re-fitted 600 steps, searched re-parents while <= 2 movable bodies
    "long-select": {"select_iters": 600, "select_top": 2, "select_search_bodies": 2},
}


def _say(msg: str) -> None:
    print(msg, flush=True)


def prepare_data(work: Path, ids: list[str] | None, split: str | None, limit: int | None,
                 protocol: str = "pd2gs") -> tuple[Path, list[str]]:
    """Generate the suite twins (once) and render ``protocol`` (rsart's capture protocols: pd2gs, the
    default, or rs-art with the single-part states too) for the selected objects."""
    from rsart.cli import main as rsart_main
    from rsart.format import read_index

    twins = work / "twins"
    if not (twins / "index.json").is_file():
        if rsart_main(["generate", "--suite", "rsart-synth", "--out", str(twins)]):
            raise SystemExit("rsart generate failed")
    index = read_index(twins / "index.json")
    if ids is None:
        if split not in index.splits:
            raise SystemExit(f"unknown split {split!r}; suite splits: {sorted(index.splits)}")
        ids = list(index.splits[split])
        if limit:  # spread the subset over categories: round-robin by category
            cats = index.extra.get("categories", {})
            by_cat: dict[str, list[str]] = {}
            for oid in ids:
                by_cat.setdefault(cats.get(oid, "?"), []).append(oid)
            order = [lst[i] for i in range(max(map(len, by_cat.values()))) for lst in by_cat.values() if i < len(lst)]
            ids = order[:limit]
    unknown = [i for i in ids if i not in index.objects]
    if unknown:
        raise SystemExit(f"not in rsart-synth: {unknown}")
    data = work / "data"
    for oid in ids:
        done = data / oid / "render.json"
        if done.is_file() and protocol in json.loads(done.read_text()).get("protocols", {}):
            continue
        t0 = time.time()
        if rsart_main(["render", str(twins / oid), "--protocol", protocol, "--out", str(data), "--size", "320x240",
                       "--background", "plain", "--no-progress"]):
            raise SystemExit(f"rsart render failed on {oid}")
        _say(f"rendered {oid} in {time.time() - t0:.0f} s")
    return data, ids


def run_all(data: Path, ids: list[str], work: Path, iters: int | None, ablations: list[str], workers: int = 1,
            backend: str = "process", address: str | None = None, threads: int | None = None) -> dict:
    """Train each object once and run every discovery configuration on its trained field, one runner task
    per object (pd2gs/runner.py: ``workers`` local processes or Ray tasks, ``threads`` each; a rerun with the
    same ``work`` skips finished objects and reuses finished stages); write one submission per
    configuration. ``ablations`` empty: train only."""
    import rsart
    from pd2gs.discovery.config import DiscoveryConfig
    from pd2gs.discovery.pipeline import dataset_block, method_block
    from pd2gs.runner import ObjectTask, assemble, default_threads, execute, summarize
    from pd2gs.train import TrainConfig

    ds = rsart.load(data)
    cfg = TrainConfig() if iters is None else TrainConfig(iters=iters)
    if threads is None:
        threads = 1 if (backend == "ray" and address) else default_threads(workers)
    variants = {name: dataclasses.replace(DiscoveryConfig(), **ABLATIONS[name]) for name in ablations}
    tasks = [ObjectTask(str(data.resolve()), oid, str(work.resolve() / "runs" / oid), cfg, variants, threads)
             for oid in ids]
    outcomes = execute(tasks, backend, workers, address, progress=True)
    summarize(outcomes, work / "summary.json", say=_say)
    timing: dict[str, dict] = {}
    for oid in ids:
        metrics_path = work / "runs" / oid / "metrics.json"
        metrics = json.loads(metrics_path.read_text()) if metrics_path.is_file() else {}
        timing[oid] = {"category": ds[oid].meta.category, "test_psnr": metrics.get("test_psnr", {}),
                       **outcomes[oid].timings}
        timing[oid].setdefault("train_s", float("nan"))
        timing[oid]["total_s"] = timing[oid]["train_s"] + timing[oid].get("discover_s[default]", float("nan"))
    if not ablations:  # --train-only
        return {"timing": timing}
    subs = {name: assemble(tasks, name, outcomes, work / "submissions" / name, method_block(variants[name]),
                           dataset_block(str(data)))
            for name in ablations}
    return {"submissions": subs, "timing": timing}


def score(data: Path, subs: dict[str, Path], work: Path, ids: list[str]) -> dict[str, dict]:
    """rsart-eval on each submission, over the objects of this run (recorded as the split ``suite-run``)."""
    from rsart.evaluation.cli import main as eval_main

    from common import select_split

    split = select_split(data, ids, "suite-run")
    out = {}
    for name, sub in subs.items():
        dest = work / "scores" / name
        if eval_main([str(sub), "--data", str(data), "--split", split, "--out", str(dest), "--overwrite"]):
            raise SystemExit(f"rsart-eval failed on {sub}")
        out[name] = json.loads((dest / "scores.json").read_text())
    return out


def _fmt(v) -> str:
    if v is None:
        return "–"
    return f"{v:.3f}" if abs(v) < 100 else f"{v:.1f}"


def _objects(scores: dict) -> list[dict]:
    """The per-object records of a scores.json (a list, or a mapping by object id)."""
    objs = scores["objects"]
    return list(objs.values()) if isinstance(objs, dict) else list(objs)


def parts_within(scores: dict, deg: float) -> tuple[int, int]:
    """(true movable parts whose matched prediction is within ``deg`` Axis Ang, all true movable parts);
    a part with no match, or of a failed (null) object, counts as a miss."""
    hit = total = 0
    for o in _objects(scores):
        parts = o.get("parts", [])
        total += o.get("n_true_movable", len(parts))
        hit += sum(1 for p in parts if (p.get("metrics", {}).get("axis_ang") is not None
                                       and p["metrics"]["axis_ang"] < deg))
    return hit, total


def report(scores: dict[str, dict], timing: dict, work: Path, ids: list[str], wall: float,
           protocol: str = "pd2gs") -> str:
    from common import cpu_description

    default = scores["default"]
    lines = [f"# PD²GS on rsart-synth ({len(ids)} objects, default CPU settings)", "",
             f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {os.cpu_count()} CPU cores "
             f"({cpu_description()}), load average at the end "
             f"{', '.join(f'{x:.1f}' for x in os.getloadavg())}; total wall time {wall / 60:.0f} min.",
             f"Capture protocol: {protocol}. Objects: {', '.join(ids)}.", "",
             "## Default configuration, per category (rsart-eval summary)", "",
             (work / "scores" / "default" / "summary.md").read_text().split("\n", 2)[2].strip(), "",
             "## Targets (means over 2-part objects, start/end mean)", "",
             "| metric | target | measured |", "|---|---|---:|"]
    overall = default["aggregate"]["overall"]["mean_of_categories"]
    lines[-2] = "| metric | target | measured | met |"
    lines[-1] = "|---|---|---:|---|"
    for m, (t, ok) in TARGETS.items():
        v = overall.get(m, {}).get("mean")
        if v is not None and m in ("count_acc", "type_acc"):
            v = 100 * v
        lines.append(f"| {m} | {t} | {_fmt(v)} | {'–' if v is None else ('yes' if ok(v) else 'no')} |")
    per_obj = [t["total_s"] / 60 for t in timing.values()]
    nf = default["aggregate"]["overall"]["n_failed_objects"]
    within, n_true = parts_within(default, 1.0)
    mpo = sum(per_obj) / len(per_obj)
    lines += [f"| objects written as null (failed) | 0 | {nf} of {len(ids)} | {'yes' if nf == 0 else 'no'} |",
              f"| true movable parts within 1° Axis Ang (unmatched = miss) | ≥ 90 % | {within} of {n_true} "
              f"({100 * within / max(1, n_true):.0f} %) | {'yes' if within >= 0.9 * n_true else 'no'} |"]
    lines += [f"| minutes per object (train + discovery) | ≤ {MINUTES_PER_OBJECT:.0f} | {mpo:.1f} | "
              f"{'yes' if mpo <= MINUTES_PER_OBJECT else 'no'} |", "",
              "## Wall time per object", "", "| object | category | train (s) | discovery (s) | total (min) |",
              "|---|---|---:|---:|---:|"]
    for oid, t in timing.items():
        lines.append(f"| {oid} | {t['category']} | {t['train_s']:.0f} | {t.get('discover_s[default]', float('nan')):.0f} | "
                     f"{t['total_s'] / 60:.1f} |")
    cols = list(dict.fromkeys([k for t in timing.values() for k in t.get("test_psnr", {}) if k != "mean"] + ["mean"]))
    lines += ["", "## Test-view PSNR of the trained fields (dB; target ≥ 28 on 2-part objects)", "",
              "| object | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
    for oid, t in timing.items():
        ps = t.get("test_psnr", {})
        lines.append(f"| {oid} | " + " | ".join(_fmt(ps.get(k)) for k in cols) + " |")
    lines += ["", "## Per part (default configuration)", "",
              "Predicted movable parts / true ones per object; per true part the matched prediction and its joint "
              "errors (`–`: not applicable or no match; the reason is in scores.json).", "",
              "| object | parts (pred/true) | part | type | matched | Axis Ang (°) | Axis Pos (×10) | Part Motion |",
              "|---|---|---|---|---|---:|---:|---:|"]
    for o in _objects(default):
        if o.get("status") != "scored":
            lines.append(f"| {o['object_id']} | null | – | – | – | – | – | – |")
            continue
        for p in o["parts"]:
            m = p.get("metrics", {})
            lines.append(f"| {o['object_id']} | {o.get('n_pred_movable', 0)}/{o['n_true_movable']} | {p['name']} | "
                         f"{p['type'][:3]}{'' if m.get('type_acc', 1) else ' (wrong)'} | {p.get('pred') or '–'} | "
                         f"{_fmt(m.get('axis_ang'))} | {_fmt(m.get('axis_pos'))} | {_fmt(m.get('part_motion'))} |")
    lines += ["", "## Ablations (same trained fields; means over categories)", "",
              "| configuration | " + " | ".join(ROW_METRICS) + " | parts within 1° | null |",
              "|---|" + "---:|" * (len(ROW_METRICS) + 2)]
    for name, sc in scores.items():
        ov = sc["aggregate"]["overall"]["mean_of_categories"]
        w, n = parts_within(sc, 1.0)
        lines.append(f"| {name} | " + " | ".join(_fmt(ov.get(m, {}).get("mean")) for m in ROW_METRICS)
                     + f" | {w}/{n} | {sc['aggregate']['overall']['n_failed_objects']} |")
    lines += ["", "type_acc and count_acc are fractions (1 = 100 %). Chamfer ×1000 (m²), Axis Pos ×10 (m), "
              "Part Motion in degrees (revolute) or metres (prismatic). Formulas: docs/evaluation.md."]
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/pd2gs-suite"), help="scratch folder (reused)")
    ap.add_argument("--split", default="two-part", help="suite split (default two-part)")
    ap.add_argument("--objects", help="comma-separated object ids (instead of --split)")
    ap.add_argument("--protocol", default="pd2gs", choices=["pd2gs", "rs-art"],
                    help="capture protocol rendered for training: pd2gs (4 multi-part states, default) or rs-art "
                         "(every state of meta.json, the single-part ones too)")
    ap.add_argument("--limit", type=int, help="at most this many objects of the split, spread over categories")
    ap.add_argument("--iters", type=int, help="training iterations (default: TrainConfig's)")
    ap.add_argument("--ablations", default=",".join(ABLATIONS), help="comma list of " + ", ".join(ABLATIONS))
    ap.add_argument("--workers", "--jobs", type=int, default=1, help="objects run at once (runner tasks)")
    ap.add_argument("--backend", default="process", choices=["process", "ray"],
                    help="local worker processes or Ray tasks (docs/pd2gs.md \"Running on a cluster\")")
    ap.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    ap.add_argument("--threads", type=int, default=None, help="CPU threads per task (default: cores / workers)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "pd2gs-rsart-synth.md",
                    help="report path: the table goes to its .md, the record to its .json")
    ap.add_argument("--train-only", action="store_true",
                    help="render and train the selected objects into --work, then stop (a later run reuses them)")
    args = ap.parse_args()
    abl = [a for a in args.ablations.split(",") if a]
    if "default" not in abl:
        abl.insert(0, "default")
    bad = [a for a in abl if a not in ABLATIONS]
    if bad:
        raise SystemExit(f"unknown ablations {bad}; choose from {list(ABLATIONS)}")
    t0 = time.time()
    args.work.mkdir(parents=True, exist_ok=True)
    data, ids = prepare_data(args.work, args.objects.split(",") if args.objects else None, args.split, args.limit,
                             args.protocol)
    if args.train_only:
        run_all(data, ids, args.work, args.iters, [], args.workers, args.backend, args.address, args.threads)
        _say(f"trained {len(ids)} objects in {(time.time() - t0) / 60:.0f} min")
        return 0
    res = run_all(data, ids, args.work, args.iters, abl, args.workers, args.backend, args.address, args.threads)
    scores = score(data, res["submissions"], args.work, ids)
    md = report(scores, res["timing"], args.work, ids, time.time() - t0, args.protocol)
    from common import write_report

    per_object = {o["object_id"]: {k: o.get(k) for k in ("status", "metrics", "failures", "n_pred_movable",
                                                          "n_true_movable", "parts")}
                  for o in _objects(scores["default"])}
    write_report(args.out, md, {"objects": ids, "timing": res["timing"], "per_object": per_object,
                                "overall": {k: v["aggregate"]["overall"] for k, v in scores.items()},
                                "categories": {k: v["aggregate"]["categories"] for k, v in scores.items()}})
    _say(md)
    return 0


if __name__ == "__main__":
    from rsart.console import guarded  # Ctrl-C or SIGTERM (the runner stops its workers first): exit 130, one line

    sys.exit(guarded(main, "pd2gs_suite", "interrupted; a rerun with the same --work resumes from the finished stages"))
