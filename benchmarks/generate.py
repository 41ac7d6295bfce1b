"""Benchmark: seconds to generate the whole rsart-synth suite (twins only) on 2 cores (target < 60 s).

Timed end to end through the CLI in a fresh interpreter (imports included), as a user runs it:

    rsart generate --suite rsart-synth --out TMP --workers 2

Repeated ``--repeats`` times (default 3); records every run, the median, the suite's size (objects,
files, bytes, triangles) and the machine's load average (other jobs share the cores).

    python benchmarks/generate.py [--repeats 3] [--workers 2] [--out benchmarks/results/generate.json]
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rsart import __version__

from common import REPO, load_avg, machine, write_result

TARGET_S = 60.0


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def run_once(workers: int) -> tuple[float, Path, tempfile.TemporaryDirectory]:
    tmp = tempfile.TemporaryDirectory(prefix="rsart-bench-gen-")
    root = Path(tmp.name) / "rsart-synth"
    cmd = [sys.executable, "-m", "rsart", "generate", "--suite", "rsart-synth", "--out", str(root),
           "--workers", str(workers)]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=REPO, env=_env(), capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"generate failed ({r.returncode}):\n{r.stderr}")
    return dt, root, tmp


def suite_stats(root: Path) -> dict:
    import trimesh

    from rsart.format import read_index, read_meta

    index = read_index(root)
    files = [p for p in root.rglob("*") if p.is_file()]
    tris = []
    for oid in index.objects:
        meta = read_meta(root / oid / "meta.json")
        n = 0
        for p in meta.parts:
            n += len(trimesh.load(root / oid / p.mesh, force="mesh", process=False).faces)
        tris.append(n)
    return {"objects": len(index.objects), "splits": {k: len(v) for k, v in index.splits.items()},
            "files": len(files), "bytes": sum(p.stat().st_size for p in files),
            "triangles_per_object": {"min": min(tris), "median": int(statistics.median(tris)), "max": max(tris)}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "generate.json")
    args = ap.parse_args(argv)
    runs, stats = [], None
    load_before = os.getloadavg()
    for k in range(args.repeats):
        dt, root, tmp = run_once(args.workers)
        runs.append(round(dt, 2))
        print(f"run {k + 1}: {dt:.1f} s", flush=True)
        if stats is None:
            stats = suite_stats(root)
        tmp.cleanup()
    med = statistics.median(runs)
    result = {
        "benchmark": "rsart generate --suite rsart-synth (twins only), fresh interpreter, wall clock",
        "target_s": TARGET_S, "median_s": round(med, 2), "runs_s": runs, "meets_target": med < TARGET_S,
        "workers": args.workers, "suite": stats,
        "machine": machine(loadavg_before=[round(x, 2) for x in load_before], loadavg_after=load_avg()),
        "rsart_version": __version__, "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    write_result(args.out, result, echo=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
