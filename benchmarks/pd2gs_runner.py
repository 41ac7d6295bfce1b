"""Benchmark: wall time of `pd2gs run` over a few tiny objects with 1 and with 2 workers (pd2gs/runner.py).

Generates and renders small rsart-synth-style objects (once, into ``--work``), then runs the full
train -> discover -> submission pipeline from scratch once per worker count (each run in its own output
folder, nothing reused), and writes the wall times, the speed-up over 1 worker and the machine's load to
``benchmarks/results/pd2gs-runner.md`` and ``.json``. Threads per task follow the runner's default
(cores / workers) unless ``--threads`` fixes them. Run it on an otherwise idle machine:

    python benchmarks/pd2gs_runner.py [--backend process|ray] [--workers 1,2] [--objects 4] [--iters 300]
                                      [--discovery default|fast]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CATEGORIES = [("storage", 1), ("drawer", 0), ("oven", 0), ("box", 0), ("door", 0), ("refrigerator", 0)]


def _say(msg: str) -> None:
    print(msg, flush=True)


def prepare(work: Path, n: int, size: str, views: int) -> tuple[Path, list[str]]:
    """Render ``n`` procedural objects (pd2gs protocol, ``views`` train views per state) into work/data
    -> (data folder, their object ids: the folder may hold more, from an earlier run with more objects)."""
    from rsart.cli import main as rsart_main
    from rsart.sources.procedural.registry import CATEGORIES as KNOWN, generate
    from rsart.twin_io import write_object

    picks = [(c, s) for c, s in CATEGORIES if c in KNOWN][:n]
    if len(picks) < n:
        raise SystemExit(f"only {len(picks)} of the benchmark's categories exist: {picks}")
    data = work / "data"
    ids = []
    for cat, seed in picks:
        g = generate(cat, seed)
        ids.append(g.object_id)
        if (data / g.object_id / "states" / "m3" / "cameras.json").is_file():
            continue
        write_object(g.twin, work / "twins" / g.object_id, object_id=g.object_id, category=g.category,
                     source=g.source)
        if rsart_main(["render", str(work / "twins" / g.object_id), "--protocol", "pd2gs", "--out", str(data),
                       "--size", size, "--views", str(views), "--test-views", "1", "--background", "plain",
                       "--workers", "1", "--no-progress"]):
            raise SystemExit(f"rsart render failed on {g.object_id}")
    return data, ids


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/pd2gs-runner-bench"), help="scratch folder")
    ap.add_argument("--backend", default="process", choices=["process", "ray"])
    ap.add_argument("--workers", default="1,2", help="comma-separated worker counts to time")
    ap.add_argument("--threads", type=int, default=None, help="threads per task (default: cores / workers)")
    ap.add_argument("--objects", type=int, default=4, help="number of tiny objects")
    ap.add_argument("--iters", type=int, default=300, help="training iterations per object")
    ap.add_argument("--size", default="128x96", help="rendered image size")
    ap.add_argument("--views", type=int, default=12, help="training views per state")
    ap.add_argument("--discovery", default="default", choices=["default", "fast"],
                    help="fast: without boundary refinement and the photometric articulation fit")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "pd2gs-runner.md")
    args = ap.parse_args(argv)
    from pd2gs.data import parse_size
    from pd2gs.discovery.config import DiscoveryConfig
    from pd2gs.run import run
    from pd2gs.train import TrainConfig

    counts = [int(w) for w in args.workers.split(",") if w]
    if not counts or min(counts) < 1:
        raise SystemExit(f"--workers: positive worker counts, got {args.workers!r}")
    args.work.mkdir(parents=True, exist_ok=True)
    data, ids = prepare(args.work, args.objects, args.size, args.views)
    w, h = parse_size(args.size)
    tcfg = TrainConfig(iters=args.iters, size=(w // 2, h // 2))
    dcfg = DiscoveryConfig() if args.discovery == "default" else DiscoveryConfig(mode="paper", refine=False)
    rows = []
    for n in counts:
        out = args.work / f"run-{args.backend}-w{n}"
        shutil.rmtree(out, ignore_errors=True)  # from scratch: nothing reused
        t0 = time.perf_counter()
        run(data, out, objects=ids, train_cfg=tcfg, discovery_cfg=dcfg, progress=False, backend=args.backend,
            workers=n, threads=args.threads)
        wall = time.perf_counter() - t0
        summary = json.loads((out / "summary.json").read_text())
        rows.append({"workers": n, "wall_s": wall, "done": len(summary["done"]), "failed": summary["failed"],
                     "load_after": os.getloadavg()})
        _say(f"{n} worker(s): {wall:.1f} s ({len(summary['done'])} done, {len(summary['failed'])} failed)")
    base = rows[0]["wall_s"]
    from common import cpu_description
    lines = [f"# pd2gs run: wall time with {', '.join(map(str, counts))} workers ({args.backend} backend)", "",
             f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {os.cpu_count()} CPU cores "
             f"({cpu_description()}); {args.objects} tiny objects "
             f"({args.size} renders, {args.views} train views per state, {args.iters} training iterations at "
             f"{w // 2}x{h // 2}, {args.discovery} discovery); threads per task: "
             f"{args.threads or 'cores / workers'}.", "",
             f"Command: `python benchmarks/pd2gs_runner.py {' '.join(argv if argv is not None else sys.argv[1:])}`",
             "", "| workers | wall (s) | speed-up | objects done | load average after (1/5/15 min) |",
             "|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['workers']} | {r['wall_s']:.1f} | {base / r['wall_s']:.2f} | {r['done']} | "
                     f"{', '.join(f'{x:.1f}' for x in r['load_after'])} |")
    from common import write_report

    record = {"backend": args.backend, "objects": args.objects, "iters": args.iters, "rows": rows}
    md_path, json_path = write_report(args.out, "\n".join(lines) + "\n", record)
    _say(f"wrote {md_path} and {json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
