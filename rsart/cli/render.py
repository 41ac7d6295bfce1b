"""``rsart render``: RS-Art-style RGB-D captures of a twin (the capture simulator, docs/render.md)."""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

DESCRIPTION = """\
Render RS-Art-style captures of a twin: per view an RGB image, a depth image and a part mask,
pixel-aligned, for the interaction states a protocol asks for.

INPUT is an object folder (meta.json + twin/), a dataset root (index.json), or a bare .urdf /
.usd/.usda/.usdc file. OUT is a dataset root: each object lands in OUT/<object_id>/ (twin copied,
states/<state>/{cameras.json, rgb/, depth/, mask/}), and OUT/index.json + OUT/checksums.sha256
are (re)written so `rsart verify OUT` works.

Protocols: pd2gs (multi states m0..m3, 50 train + 10 test views each), two-state (start and end,
100 + 10), single-joint (each joint at min and max, 100 + 10), rs-art (every state, >= 60 each,
> 400 per object), unseen (multi states at 1/6, 1/2, 5/6 of the ranges, 20 test views; added to
the output meta.json).

Conventions: metres and radians; world = object base frame, z up; cameras OpenCV (x right,
y down, z forward), camera-to-world; depth PNG 16-bit millimetres (0 = none); masks part index
+ 1 (0 = background). Cameras circle the object at 30-60 deg elevation with hand-held jitter;
intrinsics default to a RealSense D435 colour stream (640x480, fx = fy = 615).

Resumable: re-run the same command after an interruption and only unfinished views are
rendered; output is identical to an uninterrupted run (seeded per object/state/view).
"""


def register(sub: argparse._SubParsersAction) -> None:
    from ..render.booth import BACKGROUNDS
    from ..render.protocols import PROTOCOLS

    p = sub.add_parser("render", help="render RGB-D captures (RGB, depth, part masks) of a twin",
                       description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", nargs="?", type=Path, help="object folder, dataset root, .urdf or .usd file")
    p.add_argument("--suite", help="render a whole suite (rsart-synth) in OUT: generated there first if OUT is "
                                   "empty, else OUT must be that suite's root (rendered in place)")
    p.add_argument("--out", type=Path, required=True, help="output dataset root")
    p.add_argument("--protocol", choices=PROTOCOLS, default="pd2gs", help="which states and views (default pd2gs)")
    p.add_argument("--size", default="640x480", help="image WIDTHxHEIGHT (intrinsics scaled; default 640x480)")
    p.add_argument("--intrinsics", help="fx,fy,cx,cy in pixels for --size (OpenCV, pixel centres; "
                                        "default: RealSense D435 colour)")
    p.add_argument("--views", type=int, help="train views per state (overrides the protocol)")
    p.add_argument("--test-views", type=int, help="test views per state (overrides the protocol)")
    p.add_argument("--path", choices=("circle", "random"), default="circle",
                   help="train camera path: one hand-held circle per state, or wide-baseline random views")
    p.add_argument("--fill", type=float, default=0.9, help="fraction of the half field of view the object fills")
    p.add_argument("--background", choices=BACKGROUNDS, default="booth",
                   help="green chroma-key booth with pedestal (default), plain, transparent (RGBA) or random")
    p.add_argument("--sensor", action="store_true",
                   help="RealSense-like depth and colour noise (clean copies kept in rgb_clean/, depth_clean/)")
    p.add_argument("--antialias", action="store_true", help="4x MSAA RGB edges (silhouette then within 1 px of the mask)")
    p.add_argument("--geometry", choices=("visual", "mesh"), default="visual",
                   help="render the textured visuals (default) or the watertight part meshes")
    p.add_argument("--rgb-backend", choices=("auto", "pyrender", "raycast"), default="auto",
                   help="RGB via pyrender (EGL/OSMesa) or open3d ray-cast shading (no GL); auto picks pyrender if GL works")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, help="worker processes (default: all cores)")
    p.add_argument("--backend", choices=("process", "ray"), default="process",
                   help="process pool (default) or Ray (pip install ray; distributes (object, state) tasks)")
    p.add_argument("--address", help="Ray cluster address (default: start a local Ray)")
    p.add_argument("--overwrite", action="store_true", help="replace outputs rendered with other settings")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_render)


def _intrinsics(args):
    from ..camera import REALSENSE_D435_COLOR_640x480, Intrinsics
    from ..errors import RsartError

    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", args.size)
    if not m or int(m.group(1)) <= 0 or int(m.group(2)) <= 0:
        raise RsartError(f"--size {args.size!r}: expected WIDTHxHEIGHT, e.g. 640x480")
    w, h = int(m.group(1)), int(m.group(2))
    if args.intrinsics:
        try:
            fx, fy, cx, cy = (float(x) for x in args.intrinsics.split(","))
        except ValueError:
            raise RsartError(f"--intrinsics {args.intrinsics!r}: expected fx,fy,cx,cy") from None
        if fx <= 0 or fy <= 0:
            raise RsartError("--intrinsics: fx and fy must be positive")
        return Intrinsics(w, h, fx, fy, cx, cy)
    return REALSENSE_D435_COLOR_640x480.scaled(w, h)


def build_job(args):
    """The :class:`RenderJob` of parsed CLI arguments."""
    from ..errors import RsartError
    from ..render.frame import RenderOptions
    from ..render.paths import PathSpec
    from ..render.runner import RenderJob

    for name in ("views", "test_views", "workers"):
        v = getattr(args, name)
        if v is not None and v < 0:
            raise RsartError(f"--{name.replace('_', '-')} must be >= 0, got {v}")
    if not 0 < args.fill <= 1:
        raise RsartError(f"--fill must be in (0, 1], got {args.fill}")
    opts = RenderOptions(intrinsics=_intrinsics(args), background=args.background, sensor=args.sensor,
                         antialias=args.antialias, geometry=args.geometry, rgb_backend=args.rgb_backend)
    return RenderJob(protocol=args.protocol, seed=args.seed, views=args.views, test_views=args.test_views,
                     train_path=args.path, options=opts, path=PathSpec(fill=args.fill))


def _suite_dirs(name: str, out: Path, overwrite: bool, workers: int) -> list[Path]:
    """Object folders of suite ``name`` at ``out``: rendered in place, generated first if ``out`` is empty."""
    from ..errors import RsartError
    from ..render.inputs import object_dirs

    if not (out / "index.json").is_file():
        from ..sources.procedural.suite import SUITE_NAME, write_suite

        if name != SUITE_NAME:
            raise RsartError(f"unknown suite {name!r} (known: {SUITE_NAME})")
        if out.exists() and any(out.iterdir()):
            raise RsartError(f"--out {out}: neither empty nor a dataset root (index.json); "
                             f"give an empty folder to generate {name} into")
        print(f"generating {name} into {out} ...", file=sys.stderr)
        write_suite(out, workers=workers, overwrite=out.exists())
    return object_dirs(out, out, overwrite)


def _render(args) -> int:
    from ..errors import RsartError
    from ..extras import require

    if args.backend == "ray":
        require("ray", "rsart render --backend ray")
    require("render", "rsart render", modules=("open3d",))  # depth/masks ray-cast; pyrender optional (RGB)
    from ..render.inputs import object_dirs
    from ..render.raster import resolve_backend
    from ..render.runner import default_workers, finish_root, render_object_dir

    if (args.input is None) == (args.suite is None):
        raise RsartError("give exactly one of INPUT or --suite NAME")
    job = build_job(args)
    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise RsartError(f"--out {out}: exists and is not a folder")
    workers = args.workers or default_workers()
    if args.suite:
        dirs = _suite_dirs(args.suite, out, args.overwrite, workers)
    else:
        out.mkdir(parents=True, exist_ok=True)
        dirs = object_dirs(args.input, out, args.overwrite)
    backend = resolve_backend(job.options.rgb_backend)
    print(f"rsart render: {len(dirs)} object(s), protocol {job.protocol}, RGB via {backend}, "
          f"{workers} worker(s) ({args.backend})", file=sys.stderr)
    ids = []
    for d in dirs:
        plan = render_object_dir(d, job, workers=workers, backend=args.backend, address=args.address,
                                 progress=not args.no_progress, overwrite=args.overwrite)
        ids.append(plan.meta.object_id)
        print(f"{d}: {len(plan.protocol.states)} states, {plan.protocol.n_views} views", file=sys.stderr)
    finish_root(out, ids, name=args.suite)
    print(f"wrote {out} (index.json, checksums.sha256)")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Standalone entry point (``python -m rsart.cli.render``), same behaviour as ``rsart render``."""
    from . import run

    parser = argparse.ArgumentParser(prog="rsart")
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["render", *(sys.argv[1:] if argv is None else argv)])
    return run(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
