"""Benchmark: seconds to score a 42-object rsart-synth submission with 2 workers (target < 30 s).

The 42 objects are the suite's ``rs-art-like`` (18) and ``partnet-like`` (24) splits; the submission is
the ground truth itself (``make_gt_submission``: posed part meshes at start and end + joints), so the
run also checks that every real suite object scores 0 on the joint metrics. Timed: validation,
scoring (default protocol: 10k samples, 3 seeds, start + end, component filter) and writing every
report, in-process. Also timed: the ``rsart-eval`` CLI end to end (new interpreter) on the whole suite.

    python benchmarks/eval.py [--data DIR] [--workers 2] [--out benchmarks/results/eval.json]

Without ``--data`` the suite is generated into a temporary folder with ``rsart generate --suite rsart-synth``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rsart import __version__
from rsart.evaluation import EvalConfig, load_ground_truth, make_gt_submission, read_submission, score_submission
from rsart.evaluation.ground_truth import GroundTruth
from rsart.evaluation.report import build_scores, write_reports

from common import REPO, load_avg, machine, write_result

SPLITS = ("rs-art-like", "partnet-like")
TARGET_S = 30.0


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, help="an rsart-synth suite root (generated when omitted)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "eval.json")
    args = ap.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="rsart-eval-bench-") as tmp:
        tmp = Path(tmp)
        data = args.data
        if data is None:
            data = tmp / "rsart-synth"
            subprocess.run([sys.executable, "-m", "rsart", "generate", "--suite", "rsart-synth", "--out", str(data)],
                           check=True, env=_env())
        full = load_ground_truth(data)
        ids = [oid for s in SPLITS for oid in full.objects if oid in set(json.loads((data / "index.json").read_text())["splits"][s])]
        gt = GroundTruth(full.root, full.name, full.version, "+".join(SPLITS), {oid: full.objects[oid] for oid in ids})
        t0 = time.perf_counter()
        sub_path = make_gt_submission(gt, tmp / "gt42")
        t_make = time.perf_counter() - t0

        cfg = EvalConfig()
        t0 = time.perf_counter()
        sub, problems = read_submission(sub_path, gt)
        assert not problems, problems
        t_val = time.perf_counter() - t0
        results, problems = score_submission(sub, gt, cfg, workers=args.workers)
        assert not problems, problems
        t_score = time.perf_counter() - t0 - t_val
        scores = build_scores(results, config=cfg.to_dict(), config_hash=cfg.hash(), toolkit_version=__version__,
                              dataset={"name": gt.name, "version": gt.version, "split": gt.split, "root": str(data)},
                              submission={"path": str(sub_path), "method": sub.method, "dataset": sub.dataset})
        write_reports(scores, tmp / "scores42")
        t_total = time.perf_counter() - t0

        # sanity on real suite objects: GT scores 0 on joints and at most the Chamfer floor (+15%)
        max_joint = max((abs(v) for r in results.values() for p in r["parts"] for k, v in p["metrics"].items()
                         if k in ("axis_ang", "axis_pos", "part_motion")), default=0.0)
        ratios = [r["chamfer_by_state"][f"{b}@{sid}"] / r["chamfer_floor"][sid][w]
                  for r in results.values() for sid in r["chamfer_states"]
                  for b, w in (("cd_s", "static"), ("cd_w", "whole"))]
        n_parts = sum(len(r["parts"]) for r in results.values())

        # the CLI end to end on the whole suite (46 objects), new interpreter included
        sub_all = make_gt_submission(full, tmp / "gtall")
        t0 = time.perf_counter()
        cp = subprocess.run([sys.executable, "-m", "rsart.evaluation.cli", str(sub_all), "--data", str(data),
                             "--out", str(tmp / "scoresall"), "--workers", str(args.workers)],
                            capture_output=True, text=True, env=_env())
        t_cli = time.perf_counter() - t0
        assert cp.returncode == 0, cp.stderr

    result = {
        "benchmark": "rsart-eval: score a 42-object rsart-synth ground-truth submission",
        "objects": len(ids), "movable_parts": n_parts, "splits": list(SPLITS), "workers": args.workers,
        "protocol": cfg.to_dict()["chamfer"] | {"states": cfg.states},
        "seconds_total": round(t_total, 2), "seconds_validate": round(t_val, 2), "seconds_score": round(t_score, 2),
        "seconds_reports": round(t_total - t_val - t_score, 2), "seconds_per_object": round(t_score / len(ids), 3),
        "target_seconds": TARGET_S, "meets_target": t_total < TARGET_S,
        "cli_end_to_end_all_objects": {"objects": len(full.objects), "seconds": round(t_cli, 2)},
        "seconds_make_gt_submission": round(t_make, 2),
        "gt_max_joint_error": max_joint, "gt_chamfer_over_floor": {"min": round(min(ratios), 3),
                                                                    "max": round(max(ratios), 3)},
        "machine": machine(load_average_1_5_15_before=[round(x, 2) for x in load_before],
                           load_average_1_5_15_after=load_avg()),
        "rsart": __version__, "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    write_result(args.out, result, echo=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
