"""``rsart validate``, ``rsart verify`` and ``rsart info``."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check meta.json / cameras.json / index.json files against the format",
                       description="Validate a meta.json, cameras.json or index.json file, an object folder "
                                   "(meta.json + every states/*/cameras.json) or a dataset root. Prints every "
                                   "problem with its JSON path; exit 0 when valid, 2 otherwise.")
    p.add_argument("path", type=Path)
    p.set_defaults(func=_validate)

    p = sub.add_parser("verify", help="check a dataset's files against recorded SHA-256 checksums",
                       description="Compare every file under ROOT with ROOT/checksums.sha256. Reports missing, "
                                   "extra and corrupt files, and images whose size is not their camera's (PNG headers only). "
                                   "Files or folders whose symlinks lead out of ROOT are refused unread. Exit 0 "
                                   "clean, 1 problems found, 2 no checksum file or a symlink leading out of ROOT.")
    p.add_argument("root", type=Path)
    p.add_argument("--write", action="store_true", help="(re)record the checksums instead of checking them")
    p.set_defaults(func=_verify)

    p = sub.add_parser("info", help="summarise a dataset root or object folder",
                       description="Print objects, parts, joints (type, axis, limits in rad/m) and captured states.")
    p.add_argument("path", type=Path)
    p.set_defaults(func=_info)


def _validate(args) -> int:
    from ..format import validate_path

    from ..errors import escape_controls

    problems = validate_path(args.path)
    if len(problems) == 1:  # one problem: one line (each line already names its file)
        print(f"error: {escape_controls(problems[0])}", file=sys.stderr)
        return 2
    if problems:
        print(f"error: {escape_controls(str(args.path))}: {len(problems)} problems", file=sys.stderr)
        for p in problems:
            print(f"  - {escape_controls(p)}", file=sys.stderr)
        return 2
    print(f"{args.path}: valid")
    return 0


def _verify(args) -> int:
    from ..verify import verify, write_checksums

    if args.write:
        path = write_checksums(args.root)
        print(f"wrote {path}")
        return 0
    from ..errors import escape_controls

    rep = verify(args.root)
    for f in rep.outside:  # refused, never read: invalid input (exit 2)
        print(f"error: {escape_controls(str(args.root / f))}: leads out of {escape_controls(str(args.root))} "
              "(through a symlink); refused without reading it", file=sys.stderr)
    for kind in ("missing", "extra", "corrupt", "wrong_size"):
        for f in getattr(rep, kind):
            print(f"{kind.replace('_', ' ')}: {escape_controls(f)}")
    status = "ok" if rep.ok else "PROBLEMS"
    print(f"{escape_controls(str(args.root))}: {status} ({rep.checked} checked, {len(rep.missing)} missing, "
          f"{len(rep.extra)} extra, {len(rep.corrupt)} corrupt, {len(rep.wrong_size)} wrong size, "
          f"{len(rep.outside)} leading outside)")
    return 2 if rep.outside else 0 if rep.ok else 1


def _info(args) -> int:
    from ..dataset import Dataset, load

    d = load(args.path)
    objs = list(d.values()) if isinstance(d, Dataset) else [d]
    if isinstance(d, Dataset):
        print(f"{d.name} v{d.version}: {len(d)} objects; splits: "
              + ", ".join(f"{k} ({len(v)})" for k, v in d.splits.items()))
    for o in objs:
        print(f"{o.id} [{o.category}] units={o.meta.units} parts={[p.name for p in o.parts]}")
        for j in o.joints:
            lim = "unlimited" if j.limits is None else f"[{j.limits[0]:.4g}, {j.limits[1]:.4g}]"
            print(f"  {j.name}: {j.type} {o.parts[j.parent].name}->{o.parts[j.child].name} "
                  f"axis={[round(float(x), 4) for x in j.axis]} origin={[round(float(x), 4) for x in j.origin]} {lim}")
        caps = {sid: len(s.views) for sid, s in o.states.items() if s.captured}
        print(f"  states: {list(o.states)}; captured: {caps or 'none'}")
    return 0
