"""Benchmark: rasterizer forward+backward speed, `reference` vs `cpu`, in the same run.

Scene (the sizing study's): N Gaussians uniform in [-0.5, 0.5]^3, random rotations, per-axis
std 0.7 N^(-1/3) exp(0.3 randn), a camera 2.5 m away with a 40 degree FOV. Two opacity regimes:
"init" (all 0.1, as 3DGS initialises; little early termination) and "mixed" (U(0.05, 0.95),
a stand-in for a trained scene). One step = rasterize + L1 loss to a random image + backward.
Reports the median of ``--steps`` steps after warm-up, wall clock and process CPU time,
2 threads, float32, with the load average after each row (the box is shared).

    python benchmarks/pd2gs_raster.py [--steps 10] [--out benchmarks/results/pd2gs_raster.json]
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import time

import pd2gs  # noqa: F401  (sets OMP_WAIT_POLICY before torch loads)
import torch

from pd2gs.render import rasterize

from common import machine, write_result


def scene(n: int, opacity: str, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    means = torch.rand(n, 3, generator=g) - 0.5
    quats = torch.randn(n, 4, generator=g)
    scales = 0.7 * n ** (-1 / 3) * torch.exp(0.3 * torch.randn(n, 3, generator=g))
    colors = torch.rand(n, 3, generator=g)
    if opacity == "init":
        opac = torch.full((n,), 0.1)
    else:
        opac = 0.05 + 0.9 * torch.rand(n, generator=g)
    return [t.requires_grad_() for t in (means, quats, scales, colors, opac)]


def camera(size: int):
    f = 0.5 * size / math.tan(math.radians(20))
    K = torch.tensor([[f, 0, (size - 1) / 2], [0, f, (size - 1) / 2], [0, 0, 1]])
    w2c = torch.eye(4)
    w2c[2, 3] = 2.5
    return K, w2c


def time_steps(backend: str, params, size: int, steps: int, warmup: int) -> dict:
    K, w2c = camera(size)
    target = torch.rand(size, size, 3, generator=torch.Generator().manual_seed(1))
    wall, cpu = [], []
    for i in range(warmup + steps):
        t0, c0 = time.perf_counter(), time.process_time()
        out = rasterize(*params, K, w2c, size, size, backend=backend)
        (out.rgb - target).abs().mean().backward()
        t1, c1 = time.perf_counter(), time.process_time()
        for p in params:
            p.grad = None
        if i >= warmup:
            wall.append(t1 - t0)
            cpu.append(c1 - c0)
    med = statistics.median(wall)
    return {"median_ms": 1e3 * med, "min_ms": 1e3 * min(wall), "it_per_s": 1.0 / med,
            "cpu_ms_per_step": 1e3 * statistics.median(cpu)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--sizes", default="128,256")
    ap.add_argument("--counts", default="5000,20000,50000")
    ap.add_argument("--opacities", default="init,mixed")
    ap.add_argument("--out", default="benchmarks/results/pd2gs_raster.json")
    args = ap.parse_args()
    torch.set_num_threads(2)
    rows = []
    for opacity in args.opacities.split(","):
        for size in map(int, args.sizes.split(",")):
            for n in map(int, args.counts.split(",")):
                params = scene(n, opacity)
                row = {"size": size, "n": n, "opacity": opacity}
                for backend in ("cpu", "reference"):
                    row[backend] = time_steps(backend, params, size, args.steps, args.warmup)
                row["speedup_cpu_vs_reference"] = row["reference"]["median_ms"] / row["cpu"]["median_ms"]
                row["speedup_cpu_vs_reference_cpu_time"] = (row["reference"]["cpu_ms_per_step"]
                                                            / row["cpu"]["cpu_ms_per_step"])
                row["loadavg"] = os.getloadavg()
                rows.append(row)
                print(f"{opacity:5s} {size}x{size} N={n:6d}  cpu {row['cpu']['it_per_s']:6.1f} it/s  "
                      f"reference {row['reference']['it_per_s']:6.2f} it/s  "
                      f"ratio {row['speedup_cpu_vs_reference']:.1f}x", flush=True)
                _write(args, rows)  # partial results survive an interrupted run
    _write(args, rows)
    print("wrote", args.out)


def _write(args, rows) -> None:
    result = {
        "benchmark": "pd2gs_raster", "what": "rasterize + L1 + backward, float32, 2 threads",
        "machine": machine(loadavg_at_end=os.getloadavg()),
        "torch": torch.__version__, "steps": args.steps, "rows": rows,
        "note": "wall-clock on a box shared with other jobs; cpu_ms_per_step is process CPU time "
                "(all threads); loadavg per row (1/5/15 min) taken after the row",
    }
    write_result(args.out, result)


if __name__ == "__main__":
    main()
