"""``rsart generate``: procedural articulated twins and the built-in ``rsart-synth`` benchmark."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    from ..sources.procedural.catalogue import CATALOGUE  # data only: --help must not import trimesh

    cats = "\n".join(f"  {c.id:<14} {c.family:<13} {c.description}" for c in CATALOGUE)
    p = sub.add_parser(
        "generate", help="generate procedural twins (one object, or the rsart-synth suite)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Generate seeded articulated digital twins (no download needed).\n\n"
                    "  rsart generate --category drawer --seed 3 --out DIR   -> DIR/drawer-0003/\n"
                    "  rsart generate --suite rsart-synth --out DIR          -> DIR/index.json + 46 objects\n\n"
                    "Each object folder holds meta.json (parts, joints, the RS-Art states m0..m3 + single\n"
                    "min/max), twin/object.urdf, twin/object.usda, watertight twin/parts/*.ply and textured\n"
                    "twin/visual/*.obj. Metres and radians; world = object base frame, z up, base on z = 0,\n"
                    "front facing -y. Same seed -> byte-identical files.\n\ncategories:\n" + cats)
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--category", choices=sorted(c.id for c in CATALOGUE), metavar="CATEGORY", help="one category (see below)")
    what.add_argument("--suite", choices=["rsart-synth"], help="the named benchmark suite")
    p.add_argument("--seed", type=int, default=0, help="instance seed (default 0)")
    p.add_argument("--count", type=int, default=1, help="generate seeds SEED..SEED+COUNT-1 (default 1)")
    p.add_argument("--movable", type=int, default=None,
                   help="force the number of movable parts (within the category's range)")
    p.add_argument("--out", type=Path, required=True,
                   help="output folder: objects are written to OUT/<object_id>; a suite's root is OUT")
    p.add_argument("--workers", type=int, default=2, help="processes for --suite (default 2)")
    p.add_argument("--overwrite", action="store_true", help="replace existing output")
    p.set_defaults(func=_generate)


def _generate(args) -> int:
    from ..errors import RsartError
    from ..sources.procedural.registry import generate
    from ..sources.procedural.suite import write_generated, write_suite

    t0 = time.perf_counter()
    if args.suite:
        index = write_suite(args.out, workers=args.workers, overwrite=args.overwrite)
        dt = time.perf_counter() - t0
        print(f"{args.out}: {index.name} v{index.version}, {len(index.objects)} objects in {dt:.1f} s")
        for name, ids in index.splits.items():
            print(f"  split {name}: {len(ids)} objects")
        return 0
    if args.seed < 0 or args.count < 1:
        raise RsartError(f"--seed must be >= 0 and --count >= 1 (got {args.seed}, {args.count})")
    for seed in range(args.seed, args.seed + args.count):
        g = generate(args.category, seed, args.movable)
        out = args.out / g.object_id
        write_generated(g, out, overwrite=args.overwrite)
        print(f"{out}: {len(g.twin.parts) - 1} movable parts, joints "
              + ", ".join(f"{j.name} ({j.type})" for j in g.twin.joints))
    print(f"done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 0
