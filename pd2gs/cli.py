"""``pd2gs``: train a PD²GS deformable Gaussian field on an RS-Art object and render its states.

    pd2gs train OBJECT_DIR --out RUN [--states m0,m1,m2,m3] [--iters N] [--size 160x120]
                [--backend cpu|reference|gsplat] [--seed S] [--depth-init] [--resume|--overwrite]
    pd2gs render RUN --state m0 [--to m3] [--t 0.5] [--frames 9] [--views 4] [--out DIR]
    pd2gs eval RUN --object DIR --unseen u1,u2   (PSNR of unseen states via latent interpolation)

Exit status 2 for invalid input (message names the path or option), no tracebacks.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

import pd2gs  # noqa: F401  (sets OMP_WAIT_POLICY before torch loads)
from pd2gs.config_cli import add_option, overrides, value
from rsart.console import guarded
from rsart.errors import RsartError


class UsageError(RsartError):
    """Invalid command-line input."""


def _parser() -> argparse.ArgumentParser:
    """Options that set a config field are built from the field (pd2gs/config_cli.py): its type, choices,
    default and docstring live in TrainConfig / DiscoveryConfig, nowhere else."""
    from pd2gs.config import TrainConfig
    from pd2gs.discovery.config import DiscoveryConfig

    size = "x".join(map(str, TrainConfig().size))
    ap = argparse.ArgumentParser(prog="pd2gs", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="train a deformable Gaussian field on one object")
    t.add_argument("object_dir", help="RS-Art object folder (meta.json + states/*/cameras.json)")
    t.add_argument("--out", required=True, help="run folder (config.json, checkpoint.pt, metrics.json)")
    t.add_argument("--states", default=None, help="comma-separated state ids (default: all captured)")
    t.add_argument("--size", default=None, help=f"training image size WxH in pixels (default {size})")
    for name in ("iters", "backend", "seed", "init_points", "max_gaussians", "depth_init"):
        add_option(t, TrainConfig, name)
    t.add_argument("--resume", action="store_true", help="continue the run in --out")
    t.add_argument("--overwrite", action="store_true", help="start over even if --out holds a run")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    r = sub.add_parser("render", help="render a trained run at a state or between two states")
    r.add_argument("run", help="run folder written by pd2gs train")
    r.add_argument("--state", required=True, help="state id (one of the run's training states)")
    r.add_argument("--to", default=None, help="second state id for latent interpolation")
    r.add_argument("--t", type=float, default=None, help="interpolation weight in [0, 1] (needs --to)")
    r.add_argument("--frames", type=int, default=9, help="GIF frames when --to is given without --t")
    r.add_argument("--views", type=int, default=4, help="cameras in the image strip")
    add_option(r, TrainConfig, "backend")
    r.add_argument("--out", default=None, help="output folder (default RUN/renders)")
    e = sub.add_parser("eval", help="PSNR on unseen states by latent interpolation")
    e.add_argument("run", help="run folder written by pd2gs train")
    e.add_argument("--object", required=True, help="RS-Art object folder holding the unseen states")
    e.add_argument("--unseen", required=True, help="comma-separated unseen state ids")
    add_option(e, TrainConfig, "backend")
    u = sub.add_parser("run", help="end to end: train -> parts -> joints -> meshes -> rsart-submission/1",
                       description="Run PD²GS on every object of a dataset (or one object folder) and write "
                                   "OUT/submission/submission.json for rsart-eval; training runs go to OUT/runs/. "
                                   "An object that fails is written as null with its reason in failures.json.")
    u.add_argument("--data", required=True, help="dataset root (index.json) or one rendered object folder")
    u.add_argument("--objects", default=None, help="comma-separated object ids (default: all, or --split)")
    u.add_argument("--split", default=None, help="a split of index.json")
    u.add_argument("--out", required=True, help="output folder")
    add_option(u, TrainConfig, "iters")
    u.add_argument("--size", default=None, help=f"training image size WxH (default {size})")
    for name in ("mode", "counter", "n_states", "joint_rule", "mask_provider"):
        add_option(u, DiscoveryConfig, name)
    add_option(u, DiscoveryConfig, "fit_silhouette", flag="--silhouette")
    add_option(u, DiscoveryConfig, "fit_depth", flag="--depth")
    add_option(u, DiscoveryConfig, "starts")
    add_option(u, DiscoveryConfig, "canonical")
    add_option(u, DiscoveryConfig, "restarts")
    add_option(u, DiscoveryConfig, "fit_ownership", flag="--ownership")
    for name in ("select", "refine"):
        add_option(u, DiscoveryConfig, name, negate=True)
    u.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_runner_options(u)
    return ap


def _add_runner_options(p: argparse.ArgumentParser) -> None:
    """Where ``pd2gs run``'s per-object tasks run (pd2gs/runner.py; docs/pd2gs.md "Running on a cluster")."""
    g = p.add_argument_group("execution (a rerun with the same --out resumes: finished objects are skipped)")
    g.add_argument("--backend", default="process", choices=["process", "ray"],
                   help="local worker processes, or Ray tasks (pip install 'rsart[ray]')")
    g.add_argument("--workers", type=int, default=None,
                   help="objects run at once (default 1; with --address: cluster CPUs / --threads)")
    g.add_argument("--address", default=None, help="Ray cluster address (default: start a local Ray)")
    g.add_argument("--threads", type=int, default=None,
                   help="CPU threads per object task (default: cores / workers; 1 on a Ray cluster)")


def _eval(args) -> int:
    from pd2gs.data import load_frames
    from pd2gs.evaluate import eval_unseen
    from pd2gs.train import TrainConfig, load_field, write_json_atomic

    run = Path(args.run)
    if not (run / "checkpoint.pt").is_file():
        raise UsageError(f"{run}: not a pd2gs run folder (no checkpoint.pt)")
    cfg, fld = load_field(run)
    ids, frames = load_frames(args.object, args.unseen.split(","), cfg.size)
    res = {}
    for k, sid in enumerate(ids):
        res[sid] = eval_unseen(fld, [f for f in frames if f.state == k], cfg.background,
                               value(args, TrainConfig, "backend"))
        print(f"{sid}: PSNR {res[sid]['psnr']:.2f} dB (latent between states "
              f"{cfg.states[res[sid]['segment'][0]]} and {cfg.states[res[sid]['segment'][1]]}, t = {res[sid]['t']:.1f})")
    write_json_atomic(run / "unseen.json", res)
    return 0


def _train(args) -> int:
    from pd2gs.data import load_frames, parse_size
    from pd2gs.render.gsplat_backend import gsplat_status
    from pd2gs.train import TrainConfig, Trainer, write_json_atomic

    import torch

    run = Path(args.out)
    has_run = (run / "checkpoint.pt").is_file()
    if has_run and not (args.resume or args.overwrite):
        raise UsageError(f"{run}: already holds a run; pass --resume to continue or --overwrite")
    if args.resume and not has_run:
        raise UsageError(f"{run}: --resume given but there is no checkpoint.pt")
    if value(args, TrainConfig, "backend") == "gsplat" and gsplat_status():
        raise UsageError(gsplat_status())
    over = overrides(args, TrainConfig)
    if args.resume:
        cfg = TrainConfig.from_json(json.loads((run / "config.json").read_text()))
        if "iters" in over:  # a resumed run keeps its settings; only its length may change
            cfg = dataclasses.replace(cfg, iters=over["iters"])
    else:
        if args.size:
            over["size"] = parse_size(args.size)
        cfg = TrainConfig(object_dir=str(Path(args.object_dir)), **over)
    states = args.states.split(",") if (args.states and not args.resume) else (cfg.states or None)
    cfg.states, frames = load_frames(cfg.object_dir, states, cfg.size, with_depth=cfg.depth_init)
    trainer = Trainer(cfg, frames, run)
    if args.resume:
        trainer.load_state_dict(torch.load(run / "checkpoint.pt", weights_only=False))
    run.mkdir(parents=True, exist_ok=True)
    write_json_atomic(run / "config.json", asdict(cfg))
    t0, it0 = time.perf_counter(), trainer.iteration
    trainer.run(progress=not args.quiet)
    secs = time.perf_counter() - t0
    metrics = {"test_psnr": trainer.evaluate("test"), "train_psnr": trainer.evaluate("train"),
               "iterations": trainer.iteration, "seconds": secs,
               "it_per_s": (trainer.iteration - it0) / max(secs, 1e-9),
               "gaussians": trainer.field.gaussians.num, "history": trainer.history}
    write_json_atomic(run / "metrics.json", metrics)
    print(f"trained {trainer.iteration} iterations in {secs:.0f} s; test PSNR {metrics['test_psnr']}")
    return 0


def _render(args) -> int:
    import numpy as np
    import torch

    from pd2gs.data import Frame
    from pd2gs.train import TrainConfig, load_field, render_frame
    from pd2gs.viz import write_gif, write_strip

    run = Path(args.run)
    if not (run / "checkpoint.pt").is_file() or not (run / "config.json").is_file():
        raise UsageError(f"{run}: not a pd2gs run folder (needs config.json and checkpoint.pt)")
    cfg, fld = load_field(run)
    for sid in filter(None, [args.state, args.to]):
        if sid not in cfg.states:
            raise UsageError(f"unknown state {sid!r}; the run was trained on {', '.join(cfg.states)}")
    backend = value(args, TrainConfig, "backend")
    if args.t is not None and (args.to is None or not 0.0 <= args.t <= 1.0):
        raise UsageError("--t needs --to and must lie in [0, 1]")
    cams = json.loads((run / "cameras.json").read_text())
    mine = [c for c in cams if c["state"] == args.state]
    picked = ([c for c in mine if c["split"] == "test"] or mine)[:max(1, args.views)]
    frames = [Frame(torch.zeros(c["size"][1], c["size"][0], 3), None, torch.tensor(c["K"]),
                    torch.tensor(c["w2c"]), 0, "render") for c in picked]
    k0 = cfg.states.index(args.state)
    k1 = cfg.states.index(args.to) if args.to else k0
    out_dir = Path(args.out) if args.out else run / "renders"
    out_dir.mkdir(parents=True, exist_ok=True)

    @torch.no_grad()
    def image(latent, frame):
        o = render_frame(fld, latent, frame, cfg.background, backend)
        return (o.rgb.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8)

    if args.to is None or args.t is not None:
        t = args.t or 0.0
        latent = fld.interpolate(k0, k1, t)
        name = args.state if args.to is None else f"{args.state}_to_{args.to}_t{t:.2f}"
        path = write_strip([image(latent, f) for f in frames], out_dir / f"{name}.png")
        print(f"wrote {path}")
    else:
        ts = np.linspace(0, 1, max(2, args.frames))
        imgs = [image(fld.interpolate(k0, k1, float(t)), frames[0]) for t in ts]
        gif = write_gif(imgs + imgs[::-1], out_dir / f"{args.state}_to_{args.to}.gif")
        strip = write_strip(imgs, out_dir / f"{args.state}_to_{args.to}.png")
        print(f"wrote {gif} and {strip}")
    return 0


def _run(args) -> int:
    from pd2gs.data import parse_size
    from pd2gs.discovery.config import DiscoveryConfig
    from pd2gs.run import run
    from pd2gs.train import TrainConfig

    over = overrides(args, TrainConfig)
    if args.size:
        over["size"] = parse_size(args.size)
    tcfg = TrainConfig(**over)
    dcfg = DiscoveryConfig(**overrides(args, DiscoveryConfig))
    objects = [o for o in args.objects.split(",") if o] if args.objects else None
    for name in ("workers", "threads"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise UsageError(f"--{name} must be at least 1, got {getattr(args, name)}")
    if args.address and args.backend != "ray":
        raise UsageError("--address needs --backend ray")
    try:
        sub = run(args.data, args.out, objects=objects, split=args.split, train_cfg=tcfg, discovery_cfg=dcfg,
                  progress=not args.quiet, backend=args.backend, workers=args.workers, address=args.address,
                  threads=args.threads)
    except KeyError as e:
        raise UsageError(str(e)) from None
    print(f"wrote {sub}; score it with: rsart-eval {sub} --data {args.data}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``pd2gs`` console script. Every error pd2gs raises on purpose is an
    :class:`~rsart.errors.RsartError`: printed here without a traceback, exit status 2; a bug is one line,
    exit status 1 (:func:`rsart.console.guarded`)."""
    args = _parser().parse_args(argv)  # --help stays fast: torch loads only for a command
    from rsart.extras import require

    def work() -> int:
        require("pd2gs", f"pd2gs {args.cmd}")  # a missing extra is an RsartError like the others
        return {"train": _train, "render": _render, "eval": _eval, "run": _run}[args.cmd](args)

    return guarded(work, "pd2gs",
                   "interrupted (finished work is kept; resume: train --resume, run: the same command)")


if __name__ == "__main__":
    sys.exit(main())
