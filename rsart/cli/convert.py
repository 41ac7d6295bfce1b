"""``rsart convert {partnet-mobility,urdf,usd}``: import third-party twins as RS-Art object folders."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..errors import RsartError

_CONVENTIONS = """\
Output: an RS-Art object folder (meta.json; twin/parts/*.ply watertight part meshes at rest in the
world frame; twin/visual/*.obj textured meshes; twin/object.urdf; twin/object.usda), written
atomically: a failed conversion leaves nothing behind. Joints: revolute (rad) | prismatic (units);
axis (unit) and origin in the world frame at rest. States: the RS-Art protocol (m0..m3 all joints
together, s<part>min/max one joint at an extreme); joints without limits use a quarter turn.
Untrusted input: XML without DTDs/entities, mesh paths only inside the input folder.
Exit codes: 0 done, 2 invalid input (message names the file and element)."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("convert", help="import PartNet-Mobility objects, URDF or USD twins",
                       description="Convert third-party articulated objects into RS-Art object folders.\n\n"
                                   + _CONVENTIONS, formatter_class=argparse.RawDescriptionHelpFormatter)
    kinds = p.add_subparsers(dest="kind", metavar="KIND")

    pm = kinds.add_parser(
        "partnet-mobility", formatter_class=argparse.RawDescriptionHelpFormatter,
        help="PartNet-Mobility object folder(s) (mobility.urdf + meta.json + semantics.txt + textured_objs/)",
        description="Convert one PartNet-Mobility object folder (PM_OBJECT_DIR, --out = the new object "
                    "folder) or several from a root (--root PM_ROOT with --ids or --split; --out = a dataset "
                    "folder receiving pm-<id>/ folders and index.json; missing ids are reported, not fatal).\n"
                    "World frame: the URDF base frame (z up). Units: PartNet's scene units (about [-1, 1]) "
                    "unless --metric-scale is given.\n\n" + _CONVENTIONS)
    pm.add_argument("obj_dir", nargs="?", type=Path, metavar="PM_OBJECT_DIR")
    pm.add_argument("--out", type=Path, required=True, metavar="DIR")
    pm.add_argument("--root", type=Path, metavar="PM_ROOT", help="folder holding PartNet-Mobility <id>/ folders")
    g = pm.add_mutually_exclusive_group()
    g.add_argument("--ids", metavar="ID,ID,...", help="comma-separated PartNet-Mobility ids (with --root)")
    g.add_argument("--split", metavar="NAME", help="a shipped split, e.g. pd2gs-paper (with --root)")
    pm.add_argument("--object-id", help="object id (single object; default pm-<id>)")
    pm.add_argument("--metric-scale", type=float, metavar="S",
                    help="metres per PartNet unit: scale everything by S and record units 'm'")
    _common(pm)
    pm.set_defaults(func=_partnet)

    u = kinds.add_parser("urdf", formatter_class=argparse.RawDescriptionHelpFormatter,
                         help="any URDF file", description="Convert any URDF file (meshes inside its folder) "
                         "into an RS-Art object folder --out.\n\n" + _CONVENTIONS)
    u.add_argument("file", type=Path, metavar="FILE")
    u.add_argument("--out", type=Path, required=True, metavar="DIR")
    u.add_argument("--object-id")
    u.add_argument("--category", default=None)
    u.add_argument("--units", choices=["m", "scene"], default=None,
                   help="what the URDF's numbers are (default m, or what rsart recorded in its own URDFs)")
    u.add_argument("--scale", type=float, metavar="S", help="multiply geometry by S (result in metres)")
    _common(u)
    u.set_defaults(func=_urdf)

    s = kinds.add_parser("usd", formatter_class=argparse.RawDescriptionHelpFormatter,
                         help="a USD twin (UsdPhysics joints)", description="Convert a USD file with "
                         "UsdPhysics joints into an RS-Art object folder --out.\n\n" + _CONVENTIONS)
    s.add_argument("file", type=Path, metavar="FILE")
    s.add_argument("--out", type=Path, required=True, metavar="DIR")
    s.add_argument("--object-id")
    s.add_argument("--category", default=None)
    s.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    _verbosity(s)
    s.set_defaults(func=_usd)
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p.add_argument("--resolution", type=int, default=None, metavar="N",
                   help="watertight remesh grid cells across the object's diagonal (default 384)")
    _verbosity(p)


def _verbosity(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar: print only one summary line per object (and errors)")
    g.add_argument("-v", "--verbose", action="store_true",
                   help="also print how each part's watertight copy was made")


def _watertight(args):
    from ..sources.urdf_twin import WatertightConfig

    if args.resolution is None:
        return WatertightConfig()
    if not 16 <= args.resolution <= 2048:
        raise RsartError(f"--resolution must be within 16..2048, got {args.resolution}")
    return WatertightConfig(resolution=args.resolution)


def _positive(value: float | None, option: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise RsartError(f"{option} must be a positive finite number, got {value}")


def _log(args):
    return (lambda msg: print(msg, file=sys.stderr)) if getattr(args, "verbose", False) else None


def _progress(args, desc: str):
    from ..sources.urdf_twin import PartProgress

    return PartProgress(desc, enabled=not (args.quiet or getattr(args, "verbose", False)))


def _summary(meta, out: Path) -> str:
    js = ", ".join(f"{j.name} ({j.type})" for j in meta.joints)
    return f"{out}: {meta.object_id} [{meta.category}] units={meta.units} parts={len(meta.parts)} joints: {js}"


def _partnet(args) -> int:
    from ..sources.partnet import convert_partnet, convert_partnet_root, split_ids

    _positive(args.metric_scale, "--metric-scale")
    if args.root is None:
        if args.ids or args.split:
            raise RsartError("--ids/--split need --root PM_ROOT (and no PM_OBJECT_DIR)")
        if args.obj_dir is None:
            raise RsartError("give PM_OBJECT_DIR, or --root PM_ROOT with --ids or --split")
        bar = _progress(args, args.obj_dir.name)
        try:
            meta = convert_partnet(args.obj_dir, args.out, object_id=args.object_id,
                                   metric_scale=args.metric_scale, overwrite=args.overwrite,
                                   watertight=_watertight(args), log=_log(args), progress=bar)
        finally:
            bar.close()
        print(_summary(meta, args.out))
        return 0
    if args.obj_dir is not None:
        raise RsartError("give either PM_OBJECT_DIR or --root, not both")
    if args.object_id:
        raise RsartError("--object-id applies to a single object only")
    if args.split:
        ids = split_ids(args.split)
    elif args.ids:
        ids = [i.strip() for i in args.ids.split(",") if i.strip()]
    else:
        raise RsartError("--root needs --ids ID,ID,... or --split NAME")
    if not ids:
        raise RsartError("--ids lists no id")
    from tqdm import tqdm

    def done(i: str, status: str, detail) -> None:  # one summary line per object, as it finishes
        if status == "converted":
            line = _summary(detail, args.out / detail.object_id)
        elif status == "kept":
            line = f"{args.out / f'pm-{i}'}: exists, kept (pass --overwrite to redo it)"
        else:
            line = f"{i}: {status}" + (f": {detail}" if detail else "")
        tqdm.write(line, file=sys.stdout if status in ("converted", "kept") else sys.stderr)

    rep = convert_partnet_root(args.root, args.out, ids, split=args.split, metric_scale=args.metric_scale,
                               overwrite=args.overwrite, watertight=_watertight(args), log=_log(args),
                               progress_for=lambda i: _progress(args, i), on_done=done)
    print(f"{args.out}: converted {len(rep.converted)}/{len(ids)}, kept {len(rep.skipped)}, "
          f"missing {len(rep.missing)}, failed {len(rep.failed)}")
    return 2 if rep.failed or not (rep.converted or rep.skipped) else 0


def _urdf(args) -> int:
    from ..sources.urdf_twin import convert_urdf

    _positive(args.scale, "--scale")
    if args.scale is not None and args.units == "scene":
        raise RsartError("--scale converts to metres; do not combine it with --units scene")
    bar = _progress(args, args.file.name)
    try:
        meta = convert_urdf(args.file, args.out, object_id=args.object_id, category=args.category,
                            units=args.units, scale=args.scale, overwrite=args.overwrite,
                            watertight=_watertight(args), log=_log(args), progress=bar)
    finally:
        bar.close()
    print(_summary(meta, args.out))
    return 0


def _usd(args) -> int:
    try:
        from ..sources.usd_twin import convert_usd
    except ImportError as e:
        raise RsartError(f"USD import is not available in this build ({e})") from None
    from ..format import read_meta

    out = convert_usd(args.file, args.out, object_id=args.object_id, category=args.category,
                      overwrite=args.overwrite)
    print(_summary(read_meta(Path(out) / "meta.json"), Path(out)))
    return 0
