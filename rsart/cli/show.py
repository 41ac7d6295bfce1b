"""``rsart show``: a contact sheet of a twin in each of its states (PNG)."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "show", help="draw a twin in each interaction state (contact sheet PNG)",
        description="Draw OBJECT (an object folder with meta.json and twin/) in each of its states, parts in "
                    "distinct colours (with a legend) and joint axes drawn on top (revolute red, prismatic "
                    "purple), into one PNG. The camera looks at the side the parts move towards (--view "
                    "overrides it). Alternatively draw a procedural instance directly with --category/--seed. "
                    "World frame, z up, the object's units.")
    p.add_argument("object", type=Path, nargs="?", help="object folder")
    p.add_argument("--category", help="draw the procedural CATEGORY instance instead of a folder")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--movable", type=int, default=None)
    p.add_argument("--states", default=None, help="comma-separated state ids (default: all)")
    p.add_argument("--out", type=Path, required=True, help="output PNG")
    p.add_argument("--dpi", type=int, default=90)
    p.add_argument("--view", type=_view, metavar="ELEV,AZIM",
                   help="camera elevation and azimuth in degrees (default: chosen from the object)")
    p.add_argument("--views", action="store_true",
                   help="draw the rendered views instead (per captured state: RGB | depth colour-mapped | mask, "
                        "joint axes projected); needs states rendered with `rsart render`")
    p.set_defaults(func=_show)


def _view(s: str) -> tuple[float, float]:
    import math

    try:
        elev, azim = (float(x) for x in s.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r} is not ELEV,AZIM (two numbers in degrees)") from None
    if not (math.isfinite(elev) and math.isfinite(azim)):
        raise argparse.ArgumentTypeError(f"{s!r}: the angles must be finite")
    return elev, azim


def _show(args) -> int:
    from ..errors import RsartError
    from ..show import show_twin

    if (args.object is None) == (args.category is None):
        raise RsartError("give either an OBJECT folder or --category (not both)")
    if args.category is not None:
        from ..sources.procedural.registry import generate

        target = generate(args.category, args.seed, args.movable).twin
    else:
        target = args.object
    states = [s for s in args.states.split(",") if s] if args.states else None
    if args.views:
        if args.object is None:
            raise RsartError("--views needs an OBJECT folder with rendered states")
        from ..render.contact_sheet import render_sheet

        print(render_sheet(args.object, args.out))
        return 0
    out = show_twin(target, args.out, states=states, dpi=args.dpi, view=args.view)
    print(out)
    return 0
