"""Leaderboard benchmarks → benchmarks/results/leaderboard.json.

1. Sustained scoring throughput: a real ``rsart leaderboard serve`` (uvicorn subprocess on 127.0.0.1, 2 worker
   processes, rsart-eval's default Chamfer settings: 10k samples, 3 seeds) on the rsart-synth twins; N distinct
   ground-truth submissions (perturbed joints, distinct method names) are uploaded at once; throughput =
   submissions scored per minute from the first upload to the last job done.
2. Site build time with 1,000 submissions in the store (synthetic rows inserted directly: 50 methods x 20
   submissions, every rsart-synth category, aggregates and per-part scores), plots included.

    python benchmarks/leaderboard.py [--objects 46] [--uploads 6] [--workers 2] [--site-subs 1000]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path

from common import REPO, machine, test_helpers, write_result


def throughput(tmp: Path, n_objects: int, uploads: int, workers: int, samples: int) -> dict:
    lb = test_helpers("leaderboards/lb_helpers.py")
    Server, zip_folder = lb.Server, lb.zip_folder
    from leaderboards.jobs import create_token
    from leaderboards.schema import open_engine
    from rsart.evaluation import load_ground_truth, make_gt_submission
    from rsart.evaluation.gt_submission import parse_perturbation
    from rsart.sources.procedural.suite import suite_items, write_suite

    t = time.perf_counter()
    items = suite_items()[:n_objects]
    data = tmp / "rsart-synth"
    write_suite(data, workers=2, items=items)
    gen_s = time.perf_counter() - t
    gt = load_ground_truth(data)
    zips = []
    for i in range(uploads):
        sub = make_gt_submission(gt, tmp / f"sub{i}", "start,end", parse_perturbation(f"axis={i + 1}deg,seed={i}"))
        zips.append(zip_folder(Path(sub).parent, method=f"bench-{i}"))
    db = tmp / "lb.db"
    tok = create_token(open_engine(str(db)), "bench", 10_000)
    srv = Server(db, data, tmp / "work", workers=workers,
                 extra=["--chamfer-samples", str(samples), "--chamfer-seeds", "0,1,2", "--max-upload-mb", "500"]).start()
    try:
        t0 = time.perf_counter()
        ids = []
        for z in zips:
            r = srv.upload(tok, z, timeout=300)
            assert r.status_code == 202, r.text
            ids.append(r.json()["job_id"])
        up_s = time.perf_counter() - t0
        res = srv.wait_jobs(ids, timeout=3600)
        total = time.perf_counter() - t0
    finally:
        srv.kill()
    ok = sum(v["status"] == "done" for v in res.values())
    return {"objects_per_submission": len(items), "uploads": uploads, "workers": workers, "chamfer_samples": samples,
            "chamfer_seeds": [0, 1, 2], "zip_mb_each": round(len(zips[0]) / 1e6, 2), "dataset_generation_s": round(gen_s, 1),
            "upload_and_validate_s": round(up_s, 2), "wall_s": round(total, 1), "scored_ok": ok,
            "scored_per_minute": round(ok / total * 60, 2)}


CATS = ["drawer", "desk_lamp", "eyeglasses_rs", "floppy_drive", "woven_basket", "stand", "box", "door", "eyeglasses",
        "faucet", "oven", "refrigerator", "storage", "table"]


def site_build(tmp: Path, n_subs: int, n_methods: int) -> dict:
    from sqlalchemy import insert

    from leaderboards import schema as S
    from leaderboards.exports import build_site
    from leaderboards.schema import open_engine
    from rsart.evaluation.score import OBJECT_METRICS

    eng = open_engine(str(tmp / "site.db"))
    rng = random.Random(0)
    t = time.perf_counter()
    with eng.begin() as c:
        c.execute(insert(S.methods), [{"id": m + 1, "name": f"method-{m:03d}", "created_at": time.time()}
                                      for m in range(n_methods)])
        subs, aggs, scores = [], [], []
        for i in range(n_subs):
            m = i % n_methods
            sid = i + 1
            subs.append(dict(id=sid, key=f"{sid:064d}", method_id=m + 1, method_name=f"method-{m:03d}",
                             method_version=f"0.{i // n_methods}", method_json=json.dumps({"name": f"method-{m:03d}"}),
                             toolkit_name="rsart", toolkit_version="0.1.0", config_hash="0" * 64, config_json="{}",
                             dataset_name="rsart-synth", dataset_version="1", split="", submission_sha256="0" * 64,
                             track_camera_poses=rng.choice(["gt", "estimated"]), track_states=rng.choice(["2", "N"]),
                             track_part_count="inferred", track_inputs="rgb", n_objects=46, n_failed_objects=i % 3,
                             team=f"team-{m}", source="synthetic", created_at=time.time() - i))
            for cat in CATS + [S.MEAN]:
                for k in OBJECT_METRICS[:15]:
                    fail = rng.random() < 0.05
                    aggs.append(dict(submission_id=sid, category=cat, metric=k, value=None if fail else rng.random() * 10,
                                     n=3, n_failed=int(fail)))
            for cat in CATS:
                for p in range(2):
                    for k in ("axis_ang", "axis_pos", "part_motion"):
                        scores.append(dict(submission_id=sid, object_id=f"{cat}-0", category=cat, part_index=p,
                                           part_name=f"p{p}", metric=k, state="", value=rng.random(), failed=False,
                                           reason=None))
        c.execute(insert(S.submissions), subs)
        c.execute(insert(S.aggregates), aggs)
        c.execute(insert(S.scores), scores)
    insert_s = time.perf_counter() - t
    runs = []
    for _ in range(2):  # cold (every plot drawn), then a rebuild that reuses the unchanged plots
        t = time.perf_counter()
        out = build_site(eng, tmp / "site")
        runs.append(round(time.perf_counter() - t, 2))
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    return {"submissions": n_subs, "methods": n_methods, "aggregate_rows": len(aggs), "score_rows": len(scores),
            "insert_s": round(insert_s, 2), "build_cold_s": runs[0], "rebuild_s": runs[1],
            "site_mb": round(size / 1e6, 1), "files": sum(1 for p in out.rglob('*') if p.is_file())}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--objects", type=int, default=46)
    ap.add_argument("--uploads", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chamfer-samples", type=int, default=10000)
    ap.add_argument("--site-subs", type=int, default=1000)
    ap.add_argument("--site-methods", type=int, default=50)
    ap.add_argument("--only", choices=["site", "throughput"], help="run one part; the other is kept from --out")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "leaderboard.json")
    a = ap.parse_args()
    old = json.loads(a.out.read_text()) if a.only and a.out.is_file() else {}
    site, thr = old.get("site_build"), old.get("throughput")
    with tempfile.TemporaryDirectory(prefix="rsart-lb-bench-") as d:
        tmp = Path(d)
        if a.only in (None, "site"):
            site = site_build(tmp, a.site_subs, a.site_methods)
            site["loadavg_1min_after"] = round(os.getloadavg()[0], 2)
            print("site:", site, flush=True)
        if a.only in (None, "throughput"):
            thr = throughput(tmp, a.objects, a.uploads, a.workers, a.chamfer_samples)
            thr["loadavg_1min_after"] = round(os.getloadavg()[0], 2)
            print("throughput:", thr, flush=True)
    res = {"benchmark": "leaderboards: sustained scoring throughput of the server; static site build time",
           "machine": machine(),
           "throughput": thr, "site_build": site,
           "notes": "No target was set in the issue; figures are measured, on a 2-core machine shared with other jobs."}
    write_result(a.out, res)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
