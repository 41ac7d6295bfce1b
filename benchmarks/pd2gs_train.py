"""Benchmark: PD²GS training speed (and, with --object, a full default training run).

Part 1 (always): iterations/s of a full training step (deformation MLP + rasterize + L1/D-SSIM
+ backward + Adam) at 128x128 with a fixed number of Gaussians (default 20k; density control
off so the workload stays fixed), on the synthetic 2-part scene of ``pd2gs.synthetic``.
Part 2 (--object DIR): ``pd2gs train`` defaults on an RS-Art object; wall time, it/s, test PSNR
per state (and unseen-state PSNR via latent interpolation when --unseen-object is given).

    python benchmarks/pd2gs_train.py [--object DIR] [--out benchmarks/results/pd2gs_train.json]
"""
from __future__ import annotations

import pd2gs  # noqa: F401  (sets OMP_WAIT_POLICY before torch loads)

import argparse
import json
import os
import statistics
import time
from dataclasses import asdict
from pathlib import Path

import torch

from pd2gs.losses import photometric_loss, psnr
from pd2gs.render import rasterize
from pd2gs.synthetic import make_frames
from pd2gs.train import TrainConfig, Trainer

from common import machine, write_result


def _trainer(size: int, n: int, backend: str) -> Trainer:
    frames = make_frames(views=8, size=(size, size), n_gaussians=4000)
    cfg = TrainConfig(states=["a", "b", "c", "d"], size=(size, size), iters=10**6, init_points=n,
                      densify_from=10**7, opacity_reset_every=0, backend=backend)
    return Trainer(cfg, frames)


def step_speed(size: int, n: int, steps: int, backend: str) -> dict:
    """Median wall and process-CPU time of ``Trainer.step`` (the real training step)."""
    tr = _trainer(size, n, backend)
    for _ in range(3):
        tr.step()
    wall, cpu = [], []
    for _ in range(steps):
        t0, c0 = time.perf_counter(), time.process_time()
        tr.step()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    med = statistics.median(wall)
    return {"size": size, "gaussians": n, "backend": backend, "median_ms": 1e3 * med,
            "min_ms": 1e3 * min(wall), "it_per_s": 1 / med,
            "cpu_ms_per_step": 1e3 * statistics.median(cpu), "loadavg": os.getloadavg(),
            "mlp": asdict(tr.cfg.deform)}


def step_breakdown(size: int, n: int, steps: int, backend: str) -> dict:
    """Process-CPU ms per phase of a training step rebuilt from the public pieces (deform,
    rasterize, loss, backward, Adam, density statistics, quaternion renormalisation), plus the
    Adam step with ``fused=True`` as a candidate for ``train.make_optimizer``. Medians over
    ``steps``; the phases run in the order of ``Trainer.step`` (with its scale-offset prior,
    without the optional isometry prior, off by default)."""
    tr = _trainer(size, n, backend)
    fld, cfg = tr.field, tr.cfg
    fused = torch.optim.Adam([{**{k: v for k, v in g.items() if k != "params"},
                               "params": [p.detach().clone().requires_grad_() for p in g["params"]]}
                              for g in tr.opt.param_groups], eps=1e-15, fused=True)
    phases: dict[str, list[float]] = {}

    def lap(name: str, t0: float) -> float:
        t1 = time.process_time()
        phases.setdefault(name, []).append(1e3 * (t1 - t0))
        return t1

    for i in range(steps + 3):
        frame = tr._next_frame()
        t = time.process_time()
        d = fld.deform(fld.latent(frame.state))
        g = fld.gaussians
        scales, colors, opac = d.log_scales.exp(), g.colors, g.opacities
        t = lap("deform_forward", t)
        w, h = frame.size
        out = rasterize(d.means, d.quats, scales, colors, opac, frame.K, frame.w2c, w, h,
                        background=torch.tensor(cfg.background), backend=backend)
        out.means2d.retain_grad()
        t = lap("rasterize_forward", t)
        loss = photometric_loss(out.rgb, frame.rgb, cfg.lambda_dssim)
        if cfg.scale_reg_weight > 0:  # as Trainer.step (the optional isometry prior is left out)
            loss = loss + cfg.scale_reg_weight * (d.log_scales - g.log_scales).abs().mean()
        t = lap("loss_forward", t)
        tr.opt.zero_grad(set_to_none=True)
        loss.backward()
        t = lap("backward_all", t)
        tr.stats.add(out.means2d.grad, out.radii, *frame.size)
        t = lap("densify_stats", t)
        tr.opt.step()
        t = lap("adam_step", t)
        with torch.no_grad():
            q = g.quats
            q /= q.norm(dim=-1, keepdim=True)
        t = lap("quat_renorm", t)
        info = (float(loss.detach()), psnr(out.rgb, frame.rgb))
        t = lap("loss_item_and_psnr", t)
        for p_src, p_dst in zip([p for grp in tr.opt.param_groups for p in grp["params"]],
                                [p for grp in fused.param_groups for p in grp["params"]]):
            p_dst.grad = p_src.grad
        t = time.process_time()
        fused.step()
        lap("adam_step_fused_candidate", t)
        del info
    res = {k: statistics.median(v[3:]) for k, v in phases.items()}
    res["total_measured_excluding_candidate"] = sum(v for k, v in res.items()
                                                     if k != "adam_step_fused_candidate")
    return {"size": size, "gaussians": n, "backend": backend, "cpu_ms": res,
            "loadavg": os.getloadavg()}


def full_run(object_dir: str, iters: int | None, run_dir: str | None) -> dict:
    from pd2gs.data import load_frames

    cfg = TrainConfig(object_dir=object_dir)
    if iters:
        cfg.iters = iters
    cfg.states, frames = load_frames(object_dir, None, cfg.size)
    t0 = time.perf_counter()
    tr = Trainer(cfg, frames, Path(run_dir) if run_dir else None)
    tr.run(progress=False)
    secs = time.perf_counter() - t0
    return {"object": object_dir, "states": cfg.states, "views": len(frames), "iters": cfg.iters,
            "size": list(cfg.size), "seconds": secs, "it_per_s": cfg.iters / secs,
            "gaussians": tr.field.gaussians.num, "test_psnr": tr.evaluate("test"),
            "train_psnr": tr.evaluate("train")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="128")
    ap.add_argument("--counts", default="5000,20000")
    ap.add_argument("--steps", type=int, default=15)
    ap.add_argument("--backend", default="cpu")
    ap.add_argument("--object", default=None, help="RS-Art object folder for a full default run")
    ap.add_argument("--iters", type=int, default=None, help="override iterations of the full run")
    ap.add_argument("--run-dir", default=None, help="keep the full run's folder here (for pd2gs eval)")
    ap.add_argument("--skip-steps", action="store_true", help="only the full run")
    ap.add_argument("--breakdown", action="store_true", help="also time each phase of a step")
    ap.add_argument("--out", default="benchmarks/results/pd2gs_train.json")
    args = ap.parse_args()
    rows = []
    for size in map(int, args.sizes.split(",")) if not args.skip_steps else []:
        for n in map(int, args.counts.split(",")):
            row = step_speed(size, n, args.steps, args.backend)
            rows.append(row)
            print(f"{size}x{size} N={n}: {row['it_per_s']:.1f} it/s ({row['median_ms']:.0f} ms, "
                  f"cpu {row['cpu_ms_per_step']:.0f} ms)", flush=True)
    out = Path(args.out)
    # keep earlier sections (e.g. a full run measured separately) unless this run replaces them
    result = json.loads(out.read_text()) if out.is_file() else {}
    result.update({"benchmark": "pd2gs_train", "steps": rows, "loadavg_at_end": os.getloadavg(),
                   "torch": torch.__version__, "machine": machine(),
                   "note": "wall clock on a box shared with other jobs; cpu_ms_per_step is process CPU "
                           "time; loadavg per row"})
    if args.breakdown and not args.skip_steps:
        result["step_breakdown"] = [step_breakdown(size, n, args.steps, args.backend)
                                    for size in map(int, args.sizes.split(","))
                                    for n in map(int, args.counts.split(","))]
        for b in result["step_breakdown"]:
            print(b["size"], b["gaussians"], json.dumps({k: round(v, 1) for k, v in b["cpu_ms"].items()}))
    if args.object:
        result["full_run"] = full_run(args.object, args.iters, args.run_dir)
        print(json.dumps(result["full_run"], indent=1))
        result["loadavg_at_end"] = os.getloadavg()
    write_result(out, result)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
