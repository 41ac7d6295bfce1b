"""``make demo``: the main job of rsart on built-in data, end to end, printing what it does.

generate a twin (rsart-synth) -> load it -> (render an RS-Art-style capture -> run PD²GS ->
score it with rsart-eval) -> print the table and write pictures under ``--out``.
Stages after loading are added as their modules exist in this build.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

DEFAULT_OBJECT = ("storage", 0)


def _say(msg: str) -> None:
    print(msg, flush=True)


def stage_generate(out: Path, category: str, seed: int) -> Path:
    from .sources.procedural.registry import generate
    from .twin_io import write_object

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
    from .format import validate_path

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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m rsart.demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder (default demo_out/)")
    ap.add_argument("--category", default=DEFAULT_OBJECT[0])
    ap.add_argument("--seed", type=int, default=DEFAULT_OBJECT[1])
    args = ap.parse_args(argv)
    t0 = time.time()
    args.out.mkdir(parents=True, exist_ok=True)
    obj_dir = stage_generate(args.out, args.category, args.seed)
    stage_load(obj_dir)
    _say(f"demo finished in {time.time() - t0:.1f} s; outputs in {args.out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
