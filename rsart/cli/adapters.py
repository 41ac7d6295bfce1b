"""``rsart adapters | export | import``: run published baselines on rsart data through plug-in adapters.

Adapters are discovered **only** through the entry-point group ``rsart.adapters`` (rsart never imports
the packages that provide them): each entry point's name is the method name and its value an adapter
object (or a class / zero-argument factory returning one) with

* ``name``, ``title``, ``protocol`` ("two-state" | "single-joint"), ``description`` (strings);
* ``export(object_dir, out_dir, *, frame, overwrite, **options)`` -> report with ``summary()``;
* ``import_run(run_dir, object_dir, submission, *, frame, method_version, dataset, **options)`` -> report.

The built-in adapters (PARIS, ArticulatedGS, DTArt, ArtGS, REArtGS, REArtGS++) live in the
``baselines_adapters`` package and are declared as entry points by rsart's pyproject.toml; a third party
registers its own in its package metadata. Docs: docs/baselines.md.
"""
from __future__ import annotations

import argparse
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from ..errors import RsartError

GROUP = "rsart.adapters"
#: formats of ``rsart export --to`` (rsart.export.FORMATS; repeated here so --help imports nothing heavy)
EXPORT_FORMATS = ("nerfstudio", "colmap", "blender")

_CONVENTIONS = """\
Conventions: rsart objects use metres and radians, a z-up world (the object base frame) and OpenCV
cameras. Exporters convert to each method's own conventions (OpenGL/Blender camera axes, degrees in
trans.json, millimetre depth PNGs; --frame paris|y-up to land in the peers' PartNet-Mobility GT frame or
PartNet's y-up annotation frame) and importers convert back."""


def discover() -> dict[str, tuple[Any, str]]:
    """Method name -> (adapter or None, origin or load error) for every entry point of ``rsart.adapters``."""
    out: dict[str, tuple[Any, str]] = {}
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        if ep.name in out:
            continue
        origin = f"{ep.value}" + (f" ({ep.dist.name})" if getattr(ep, "dist", None) is not None else "")
        try:
            obj = ep.load()
            if not (hasattr(obj, "export") and hasattr(obj, "import_run")) or isinstance(obj, type):
                obj = obj()
            if not (hasattr(obj, "export") and hasattr(obj, "import_run")):
                raise TypeError("not an adapter (needs export() and import_run())")
            out[ep.name] = (obj, origin)
        except Exception as e:  # one broken plug-in must not hide the others
            out[ep.name] = (None, f"{origin}: failed to load: {type(e).__name__}: {e}")
    return out


def get(name: str) -> Any:
    ads = discover()
    if not ads:
        raise RsartError(f"no adapters installed (entry-point group {GROUP!r} is empty); install rsart with "
                         f"its baselines_adapters package, or a package that registers adapters")
    if name not in ads:
        raise RsartError(f"no adapter {name!r} (available: {', '.join(sorted(ads))})")
    obj, origin = ads[name]
    if obj is None:
        raise RsartError(f"adapter {name!r}: {origin}")
    return obj


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("adapters", help="list the installed method adapters (plug-ins)",
                       description="Method adapters found in the entry-point group 'rsart.adapters'.")
    asub = p.add_subparsers(dest="adapters_command", metavar="ACTION")
    pl = asub.add_parser("list", help="list adapters: method, protocol, description, where it comes from")
    pl.set_defaults(func=_list)
    p.set_defaults(func=_list)

    pe = sub.add_parser("export", help="write an rsart object for a training tool (--to) or a method (--method)",
                        description="Export OBJECT (an object folder with rendered states).\n\n"
                                    "--to nerfstudio|colmap|blender: the inputs NeRF / Gaussian-splatting code "
                                    "reads, one folder OUT/<state>/ per state (--state ID, repeatable, or "
                                    "--all-states = every captured state, the default): nerfstudio "
                                    "transforms.json with train/val/test file lists and binary masks; a COLMAP "
                                    "model sparse/0 (PINHOLE camera, points from back-projected depth) with "
                                    "images/ (training views only; test views in test/); Blender "
                                    "transforms_{train,val,test}.json (OpenGL camera axes, camera_angle_x). "
                                    "Test views are never in a training list. Docs: docs/export.md.\n\n"
                                    "--method NAME: the input layout of a baseline method (adapter plug-in), with "
                                    "that method family's capture protocol (two-state or single-joint); "
                                    "OUT/README.txt gives the commands to run in the method's repository. "
                                    "--method nerfstudio|colmap|blender means --to.\n\n" + _CONVENTIONS,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    pe.add_argument("object", type=Path, help="object folder (meta.json + rendered states)")
    how = pe.add_mutually_exclusive_group(required=True)
    how.add_argument("--to", choices=EXPORT_FORMATS, help="training-tool format (see above)")
    how.add_argument("--method", help="adapter name (see `rsart adapters list`)")
    which = pe.add_mutually_exclusive_group()
    which.add_argument("--state", action="append", metavar="ID", help="state to export (repeatable; with --to)")
    which.add_argument("--all-states", action="store_true", help="every captured state (default; with --to)")
    pe.add_argument("--out", type=Path, required=True,
                    help="output folder (created atomically; an existing empty folder is fine)")
    pe.add_argument("--frame", default="z-up", choices=("z-up", "paris", "y-up"),
                    help="method world frame: z-up = rsart's world (default); paris = the peers' z-up GT frame of "
                         "PartNet-Mobility objects; y-up = PartNet's y-up annotation frame")
    pe.add_argument("--overwrite", action="store_true", help="replace an existing OUT")
    pe.set_defaults(func=_export)

    pi = sub.add_parser("import", help="add a method's outputs for one object to a submission file",
                        description="Read RUN_DIR (the method's output folder for OBJECT) and add or replace "
                                    "OBJECT's entry in SUBMISSION (rsart-submission/1; created if missing; "
                                    "written atomically). Score it with `rsart-eval SUBMISSION --data ROOT`.\n\n"
                                    + _CONVENTIONS, formatter_class=argparse.RawDescriptionHelpFormatter)
    pi.add_argument("run_dir", type=Path, help="the method's output folder for this object")
    pi.add_argument("--method", required=True, help="adapter name (see `rsart adapters list`)")
    pi.add_argument("--object", required=True, help="object id (with --data) or object folder")
    pi.add_argument("--data", type=Path, help="dataset root (index.json) or object folder holding OBJECT")
    pi.add_argument("--into", type=Path, required=True, help="submission JSON to create or update")
    pi.add_argument("--frame", default="z-up", choices=("z-up", "paris", "y-up"),
                    help="method world frame used at export (default z-up)")
    pi.add_argument("--method-version", help="version of the method's code (recorded in the submission)")
    pi.add_argument("--failed", metavar="REASON", help="record the object as failed (null entry) instead of reading RUN_DIR")
    pi.set_defaults(func=_import)


def _list(args) -> int:
    ads = discover()
    if not ads:
        print(f"no adapters installed (entry-point group {GROUP!r} is empty)")
        return 0
    w = max(len(n) for n in ads)
    for name, (obj, origin) in ads.items():
        if obj is None:
            print(f"{name:<{w}}  BROKEN  {origin}")
        else:
            print(f"{name:<{w}}  {getattr(obj, 'protocol', '?'):<12}  {getattr(obj, 'description', '')}  [{origin}]")
    return 0


def _export(args) -> int:
    fmt = args.to or (args.method if args.method in EXPORT_FORMATS else None)
    if fmt is not None:
        return _export_format(args, fmt)
    if args.state or args.all_states:
        raise RsartError("--state/--all-states apply to --to nerfstudio|colmap|blender; an adapter (--method) "
                         "exports the states of its own capture protocol")
    ad = get(args.method)
    rep = ad.export(args.object, args.out, frame=args.frame, overwrite=args.overwrite)
    print(rep.summary() if hasattr(rep, "summary") else rep)
    print(f"next: the commands in {args.out / 'README.txt'}")
    return 0


def _export_format(args, fmt: str) -> int:
    from ..dataset import RSArtObject, load
    from ..export import export

    if args.frame != "z-up":
        raise RsartError(f"--frame {args.frame} applies to adapters (--method); --to {fmt} exports in rsart's world frame")
    obj = load(args.object)
    if not isinstance(obj, RSArtObject):
        raise RsartError(f"{args.object}: a dataset root; export one object folder of it (e.g. {args.object}/<id>)")
    written = export(obj, fmt, args.out, states=args.state, overwrite=args.overwrite)
    for w in written:
        print(f"{fmt}: {w}")
    hint = {"nerfstudio": "ns-train splatfacto --data {d} nerfstudio-data",
            "colmap": "python train.py -s {d}   (3D Gaussian Splatting; test views: {d}/test)",
            "blender": "python train.py -s {d}   (3D Gaussian Splatting, Blender/NeRF-synthetic reader)"}[fmt]
    print("next: " + hint.format(d=written[0].parent if fmt != "colmap" else written[0].parent.parent))
    return 0


def _dataset_of(data: Path | None) -> dict | None:
    if data is not None and (data / "index.json").is_file():
        from ..format import read_index

        idx = read_index(data / "index.json")
        return {"name": idx.name, "version": str(idx.version)}
    return None


def _object_dir(ref: str, data: Path | None) -> Path:
    p = Path(ref)
    if (p / "meta.json").is_file():
        return p
    if data is None:
        raise RsartError(f"--object {ref}: not an object folder; give --data ROOT to look the id up")
    if (data / "meta.json").is_file():
        return data
    if (data / "index.json").is_file():
        from ..format import read_index

        if ref not in read_index(data / "index.json").objects:
            raise RsartError(f"{data}: no object {ref!r} in index.json")
        return data / ref
    raise RsartError(f"{data}: neither a dataset root (index.json) nor an object folder (meta.json)")


def _import(args) -> int:
    ad = get(args.method)
    obj_dir = _object_dir(args.object, args.data)
    if args.failed is not None:
        from ..format import read_meta

        meta = read_meta(obj_dir)
        _write_failure(ad, args.into, meta.object_id, args.failed, args.method_version, _dataset_of(args.data))
        print(f"{args.method}: recorded {meta.object_id} as failed in {args.into}")
        return 0
    rep = ad.import_run(args.run_dir, obj_dir, args.into, frame=args.frame, method_version=args.method_version,
                        dataset=_dataset_of(args.data))
    print(rep.summary() if hasattr(rep, "summary") else rep)
    print(f"score: rsart-eval {args.into} --data {args.data or obj_dir}")
    return 0


def _write_failure(ad: Any, submission: Path, object_id: str, reason: str, version: str | None,
                   dataset: dict | None) -> None:
    if hasattr(ad, "record_failure"):
        ad.record_failure(submission, object_id, reason, method_version=version, dataset=dataset)
        return
    raise RsartError(f"adapter {ad.name!r} cannot record failures")

