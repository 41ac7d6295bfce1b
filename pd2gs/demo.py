"""``make demo``: the main job of rsart on built-in data, end to end, printing what it does.

generate a twin (rsart-synth) -> load it -> render an RS-Art-style capture (pd2gs protocol) ->
run PD²GS (train, discover parts, joints, meshes) -> score the submission with rsart-eval ->
print the table; pictures and every intermediate file are written under ``--out``.

It lives in pd2gs (which may use rsart; rsart never imports pd2gs) and calls the public
commands (`rsart render`, :mod:`pd2gs.run`, `rsart-eval`) the way a user would.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

DEFAULT_OBJECT = ("storage", 1)  # two doors: distinct revolute motions


def _say(msg: str) -> None:
    print(msg, flush=True)


def stage_generate(out: Path, category: str, seed: int) -> Path:
    from rsart.sources.procedural.registry import generate
    from rsart.twin_io import write_object

    g = generate(category, seed)
    obj_dir = out / g.object_id
    if (obj_dir / "meta.json").is_file():
        _say(f"[1] twin {g.object_id}: already generated at {obj_dir}")
        return obj_dir
    write_object(g.twin, obj_dir, object_id=g.object_id, category=g.category, source=g.source)
    _say(f"[1] generated twin {g.object_id} ({len(g.twin.parts)} parts, {len(g.twin.joints)} joints) -> {obj_dir}")
    return obj_dir


def stage_load(obj_dir: Path) -> None:
    import rsart
    from rsart.format import validate_path

    problems = validate_path(obj_dir)
    if problems:
        raise SystemExit("demo: generated object is invalid:\n" + "\n".join(problems))
    obj = rsart.load(obj_dir)
    _say(f"[2] rsart.load -> {obj}")
    for j in obj.joints:
        lim = "unlimited" if j.limits is None else f"[{j.limits[0]:.3f}, {j.limits[1]:.3f}]"
        unit = "rad" if j.type == "revolute" else "m"
        _say(f"      joint {j.name}: {j.type}, axis {[round(float(x), 3) for x in j.axis]}, limits {lim} {unit}")
    twin = obj.twin
    for sid in (obj.meta.eval_states["start"], obj.meta.eval_states["end"]):
        lo, hi = twin.bounds(obj.states[sid].values)
        _say(f"      state {sid}: object spans {[round(float(x), 3) for x in hi - lo]} m")


def stage_render(obj_dir: Path, data: Path, size: str, views: int) -> Path:
    from rsart.cli import main as rsart_main

    t0 = time.time()
    code = rsart_main(["render", str(obj_dir), "--protocol", "pd2gs", "--out", str(data), "--size", size,
                       "--views", str(views), "--background", "plain", "--no-progress"])
    if code:
        raise SystemExit(f"demo: rsart render failed (exit {code})")
    out = data / obj_dir.name
    from rsart.render.contact_sheet import render_sheet

    sheet = render_sheet(out, data.parent / "capture.png")
    _say(f"[3] rendered the pd2gs protocol ({size}, {views} train views per state) in {time.time() - t0:.0f} s "
         f"-> {out}; picture: {sheet}")
    return out


def stage_pd2gs(data: Path, out: Path, iters: int) -> Path:
    from . import run
    from .train import TrainConfig

    t0 = time.time()
    sub = run.run(data, out, train_cfg=TrainConfig(iters=iters), progress=True)
    _say(f"[4] PD²GS: trained, discovered parts and joints, extracted meshes in {time.time() - t0:.0f} s -> {sub}")
    return sub


def stage_eval(sub: Path, data: Path, out: Path) -> None:
    from rsart.evaluation.cli import main as eval_main

    code = eval_main([str(sub), "--data", str(data), "--out", str(out)])
    if code:
        raise SystemExit(f"demo: rsart-eval failed (exit {code})")
    _say(f"[5] scored with rsart-eval -> {out}/summary.md")
    _say((out / "summary.md").read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pd2gs.demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder (default demo_out/)")
    ap.add_argument("--category", default=DEFAULT_OBJECT[0])
    ap.add_argument("--seed", type=int, default=DEFAULT_OBJECT[1])
    ap.add_argument("--size", default="320x240", help="render size WxH (PD²GS trains at 160x120)")
    ap.add_argument("--views", type=int, default=50, help="train views per state (the paper: 50)")
    ap.add_argument("--iters", type=int, default=3000, help="PD²GS training iterations")
    ap.add_argument("--twin-only", action="store_true", help="stop after generating and loading the twin")
    args = ap.parse_args(argv)
    t0 = time.time()
    args.out.mkdir(parents=True, exist_ok=True)
    obj_dir = stage_generate(args.out / "twins", args.category, args.seed)
    stage_load(obj_dir)
    if not args.twin_only:
        data = stage_render(obj_dir, args.out / "data", args.size, args.views)
        sub = stage_pd2gs(data.parent, args.out / "pd2gs_run", args.iters)
        stage_eval(sub, data.parent, args.out / "scores")
    _say(f"demo finished in {time.time() - t0:.1f} s; outputs in {args.out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
