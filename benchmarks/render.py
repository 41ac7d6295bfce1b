"""Benchmark of the capture simulator: frames/s of RGB + depth + mask at 640x480, PNGs written.

Twins: "simple" (three face-coloured boxes, 36 triangles) and "100k" (a procedural textured
storage unit whose visuals are subdivided 4x, ~93k triangles). For each: the full pipeline of
``rsart render`` (green booth, pd2gs protocol, 4 states, PNG writes) with 1 and 2 worker
processes, timed as wall clock including worker start-up, and as steady-state throughput
(from the first finished task to the last). Also the per-frame time of the render call alone
(no PNG) in one process. Writes benchmarks/results/render.json.

The machine is shared, so wall-clock figures depend on the load (recorded at start and end).
CPU time is much less load-dependent: ``cpu_s_per_frame_total`` counts this process and its joined
workers (start-up imports included), ``cpu_s_per_frame_in_tasks`` only the render tasks (scene builds,
rendering, PNG writes; GL driver threads included). ``fps_projected_idle`` = workers /
cpu_s_per_frame_in_tasks is what that many otherwise idle cores would reach if the workers scaled
perfectly -- an upper bound, not a measurement.

Run: PYTHONPATH=. .venv/bin/python benchmarks/render.py [--views 30]
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import math
import multiprocessing as mp
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from rsart.format import Joint
from rsart.kinematics import Twin, TwinPart
from rsart.render.frame import RenderOptions, StateRenderer
from rsart.render.paths import circular_path, fit_radius
from rsart.render.raster import resolve_backend
from rsart.render.runner import RenderJob, init_worker, pending_tasks, plan_object, render_task, write_plan
from rsart.twin_io import read_twin, write_object

from common import load_avg, machine, write_result

TARGETS = {"simple": 15.0, "100k": 5.0}  # frames/s with 2 workers


def simple_twin() -> Twin:
    def box(ext, c, colour):
        m = trimesh.creation.box(extents=ext)
        m.apply_translation(c)
        m.visual.face_colors = colour
        return m

    parts = [TwinPart(0, "body", box([0.4, 0.4, 0.4], [0, 0, 0.2], (200, 170, 120, 255))),
             TwinPart(1, "door", box([0.02, 0.36, 0.36], [0.212, 0, 0.2], (40, 90, 200, 255))),
             TwinPart(2, "drawer", box([0.3, 0.2, 0.1], [0, -0.26, 0.25], (30, 170, 60, 255)))]
    joints = [Joint("door_hinge", "revolute", 0, 1, np.array([0.0, 0.0, -1.0]), np.array([0.222, -0.18, 0.0]),
                    (0.0, math.pi / 2)),
              Joint("drawer_slide", "prismatic", 0, 2, np.array([0.0, -1.0, 0.0]), np.array([0.0, -0.2, 0.25]),
                    (0.0, 0.2))]
    return Twin("simple", parts, joints)


def dense_twin(subdivisions: int = 4) -> Twin:
    from rsart.sources.procedural.registry import generate

    twin = generate("storage", 1).twin
    for p in twin.parts:
        vis = []
        for v in p.render_meshes():
            for _ in range(subdivisions):
                v = v.subdivide()
            vis.append(v)
        p.visuals = vis
    return twin


def triangles(twin: Twin) -> int:
    return int(sum(len(m.faces) for p in twin.parts for m in p.render_meshes()))


def render_only_ms(twin: Twin, n: int = 20) -> float:
    """Mean ms per render call (RGB + depth + mask, no PNG) in this process, after one warm-up frame."""
    opt = RenderOptions()
    values = {j.name: (j.limits[1] if j.limits else 0.0) * 0.5 for j in twin.joints}
    b = twin.bounds(values)
    r = fit_radius(b, opt.intrinsics)
    sr = StateRenderer(twin, values, opt, b, r)
    poses = circular_path(b.mean(0), r, n + 1, np.random.default_rng(0))
    rng = np.random.default_rng(0)
    sr.render(poses[0], rng)
    t = time.perf_counter()
    for p in poses[1:]:
        sr.render(p, rng)
    dt = (time.perf_counter() - t) / n * 1000
    sr.close()
    return dt


def pipeline(obj_dir: Path, views: int, workers: int) -> dict:
    """Render the pd2gs protocol (4 states x ``views``) of a fresh copy; wall and steady-state frames/s."""
    job = RenderJob(protocol="pd2gs", views=views, test_views=0)
    twin = read_twin(obj_dir)
    from rsart.format import read_meta

    plan = plan_object(obj_dir, twin, read_meta(obj_dir), job)
    write_plan(plan, job)
    tasks = pending_tasks(plan, twin, job)
    n = sum(len(t.views) for t in tasks)
    cpu0 = _cpu_seconds()
    t0 = time.perf_counter()
    first = None
    task_cpu = 0.0
    if workers == 1:
        init_worker(0)
        for t in tasks:
            task_cpu += timed_task(t)[1]
            first = first or time.perf_counter()
        first_views = len(tasks[0].views)
    else:
        ctx = mp.get_context("spawn")
        with cf.ProcessPoolExecutor(workers, mp_context=ctx, initializer=init_worker, initargs=(1,)) as ex:
            futs = [ex.submit(timed_task, t) for t in tasks]
            first_views = 0
            for fu in cf.as_completed(futs):
                k, c = fu.result()
                task_cpu += c
                if first is None:
                    first, first_views = time.perf_counter(), k
    wall = time.perf_counter() - t0
    cpu = _cpu_seconds() - cpu0
    steady = (n - first_views) / max(time.perf_counter() - first, 1e-9) if first else float("nan")
    return {"workers": workers, "views": n, "wall_s": round(wall, 2), "fps_wall": round(n / wall, 2),
            "fps_steady": round(steady, 2), "cpu_s_per_frame_total": round(cpu / n, 4),
            "cpu_s_per_frame_in_tasks": round(task_cpu / n, 4),
            "fps_projected_idle": round(min(workers, os.cpu_count() or 1) * n / task_cpu, 2)}


def timed_task(task) -> tuple[int, float]:
    """Run one render task; returns (views, CPU seconds of this process -- all its threads -- meanwhile)."""
    c = time.process_time()
    n = render_task(task)
    return n, time.process_time() - c


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process and its finished children (worker pools are joined)."""
    import resource

    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", type=int, default=30, help="train views per state (4 states)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "render.json")
    args = ap.parse_args()
    results = {"benchmark": "render", "image": "640x480", "background": "booth", "sensor": False,
               "rgb_backend": resolve_backend("auto"), "machine": machine(load_avg_at_start=load_avg()),
               "targets_fps_2_workers": TARGETS, "twins": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for name, twin in (("simple", simple_twin()), ("100k", dense_twin())):
            rec = {"triangles": triangles(twin), "render_only_ms_per_frame_1_process": round(render_only_ms(twin), 1)}
            runs = []
            for workers in (1, 2):
                obj = Path(tmp) / f"{name}-{workers}"
                write_object(twin, obj, object_id=f"{name}-{workers}", category="bench",
                             source={"kind": "procedural", "id": name}, write_usd=False)
                runs.append(pipeline(obj, args.views, workers))
                print(name, runs[-1], flush=True)
            rec["pipeline"] = runs
            two = runs[1]
            rec["target_fps_2_workers"] = TARGETS[name]
            rec["meets_target_wall"] = two["fps_wall"] >= TARGETS[name]
            rec["meets_target_steady"] = two["fps_steady"] >= TARGETS[name]
            rec["meets_target_projected_idle"] = two["fps_projected_idle"] >= TARGETS[name]
            results["twins"][name] = rec
    results["load_avg_at_end"] = load_avg()
    write_result(args.out, results, echo=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
