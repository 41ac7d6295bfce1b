"""``rsart-eval``: validate and score a submission; write reference submissions.

    rsart-eval SUBMISSION --data ROOT [--split NAME] [--out DIR] [--states start,end|all] [--workers N]
    rsart-eval SUBMISSION --data ROOT --validate-only
    rsart-eval --make-gt-submission --data ROOT --out DIR [--perturb-joints axis=5deg,pivot=0.02,motion=3deg,seed=0]

Exit codes: 0 scored / valid / written; 2 invalid submission, data or usage (every problem is listed
with its JSON path, no traceback); 1 an unexpected internal error.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..console import guarded
from ..errors import Problem, RsartError

DESCRIPTION = """\
Score an articulated-object reconstruction submission (rsart-submission/1, docs/evaluation.md §1) against the
ground-truth twins of an RS-Art dataset, with the literature's metrics (PARIS -> DTArt -> ArtGS):
Chamfer CD-s/CD-m/CD-w (x1000, squared distance units), Axis Ang (deg), Axis Pos (x10 scene units,
revolute only), Part Motion (deg for revolute, scene units for prismatic), joint-type and part-count
accuracy, and PSNR/SSIM/part-mask scores when renders or masks are submitted. Each mean comes as in the
papers (failures left out, marked *), as a penalised mean (a failure counts the metric's worst value) and
with a completion rate.
Joint axis/origin in a submission are in the object's world frame at the eval 'start' state.
Submission format, formulas and conventions: docs/evaluation.md (in the rsart repository)."""


def _mb(s: str) -> int:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r} is not a number of megabytes") from None
    if not v > 0:
        raise argparse.ArgumentTypeError("must be positive")
    return int(v * 1024 ** 2)


def _seeds(s: str) -> tuple[int, ...]:
    try:
        out = tuple(int(x) for x in s.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r} is not a comma list of integers") from None
    if not out:
        raise argparse.ArgumentTypeError("give at least one seed")
    return out


def _positive(s: str) -> int:
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r} is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError("must be >= 1")
    return v


def add_eval_arguments(p: argparse.ArgumentParser, submission_required: bool) -> None:
    """Arguments shared by ``rsart-eval`` and ``rsart validate-submission``."""
    p.add_argument("submission", type=Path, nargs=None if submission_required else "?",
                   help="the submission JSON file (mesh paths are relative to its folder)")
    p.add_argument("--data", type=Path, help="dataset root (index.json) or a single object folder (meta.json)")
    p.add_argument("--split", help="score only this split of index.json (default: every object)")
    p.add_argument("--max-mesh-mb", type=_mb, default=200 * 1024 ** 2, metavar="MB",
                   help="largest mesh file accepted (default 200)")
    p.add_argument("--max-total-mb", type=_mb, default=20 * 1024 ** 3, metavar="MB",
                   help="largest total of referenced files (default 20480)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rsart-eval", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_eval_arguments(p, submission_required=False)
    p.add_argument("--out", type=Path, help="output folder (default: <submission folder>/eval)")
    p.add_argument("--states", default="start,end",
                   help="Chamfer states: comma list of state ids or start/end, or 'all' (default start,end)")
    p.add_argument("--workers", type=_positive, default=None, help="processes (default: all cores)")
    p.add_argument("--validate-only", action="store_true", help="only validate (and parse every mesh); exit 2 if invalid")
    p.add_argument("--no-component-filter", action="store_true",
                   help="do not drop predicted components < 10%% of the largest (DTArt's filter is on by default)")
    # defaults None: ChamferConfig owns them (the pinned reference scores hold them; --help must not import it)
    p.add_argument("--chamfer-samples", type=_positive, default=None, help="points per mesh (default 10000)")
    p.add_argument("--chamfer-seeds", type=_seeds, default=None, help="sampling seeds (default 0,1,2)")
    p.add_argument("--make-gt-submission", action="store_true",
                   help="write the ground truth as a submission folder at --out (meshes + joints)")
    p.add_argument("--perturb-joints", metavar="SPEC",
                   help="with --make-gt-submission: perturb the joints, e.g. "
                        "axis=5deg,pivot=0.02,motion=3deg,travel=0.01,seed=0 (camera poses: rsart perturb-poses)")
    p.add_argument("--perturb", dest="perturb_old", metavar="SPEC", help="deprecated spelling of --perturb-joints")
    p.add_argument("--overwrite", action="store_true", help="with --make-gt-submission: replace an existing --out")
    return p


def print_problems(source: str, problems: list[Problem]) -> None:
    """One problem on one line (``error: SUB: invalid submission: path: problem``), several as a count and
    one line each; control characters escaped (:func:`rsart.errors.format_problems`)."""
    from ..errors import format_problems

    print(f"error: {format_problems(problems, f'{source}: invalid submission')}", file=sys.stderr)


def validate(args, check_meshes: bool = True, workers: int | None = None):
    """Validate ``args.submission`` against ``args.data`` -> (submission, gt, problems)."""
    from .ground_truth import load_ground_truth
    from .submission import Limits, read_submission

    limits = Limits(max_mesh_bytes=args.max_mesh_mb, max_total_bytes=args.max_total_mb)
    gt = load_ground_truth(args.data, args.split) if args.data is not None else None
    sub, problems = read_submission(args.submission, gt, limits)
    if sub is not None and check_meshes:
        problems = check_mesh_content(sub, limits, workers)
    return sub, gt, problems


def _check_one(item) -> list[tuple[str, str]]:
    from .submission import MeshError, load_mesh

    jpath, path, max_bytes = item
    try:
        load_mesh(path, max_bytes)
    except MeshError as e:
        return [(jpath, f"{path.name}: {e}")]
    except OSError as e:
        return [(jpath, f"{path.name}: cannot be read ({e.strerror})")]
    return []


def check_mesh_content(sub, limits, workers: int | None = None) -> list[Problem]:
    """Parse every mesh of the submission (in parallel); a Problem for each unusable one."""
    from concurrent.futures import ProcessPoolExecutor

    from .score import default_workers

    items = []
    for oid, obj in sub.results.items():
        if obj is None:
            continue
        for part in obj.parts:
            items += [(f"{part.json_path}.meshes.{sid}", p, limits.max_mesh_bytes) for sid, p in part.meshes.items()]
        items += [(f"results.{oid}.whole.{sid}", p, limits.max_mesh_bytes) for sid, p in obj.whole.items()]
    workers = workers or default_workers()
    if workers <= 1 or len(items) < 8:
        outs = [_check_one(i) for i in items]
    else:
        with ProcessPoolExecutor(max_workers=workers) as ex:
            outs = list(ex.map(_check_one, items, chunksize=8))
    return [Problem(j, m) for o in outs for j, m in o]


def _toolkit_version() -> str:
    from .. import __version__

    return __version__


def _score(args) -> int:
    from ..io import sha256_file
    from ..metrics.chamfer import ChamferConfig
    from .report import build_scores, write_reports
    from .score import EvalConfig, score_submission
    from .submission import Limits

    sub, gt, problems = validate(args, check_meshes=False)
    if problems:
        print_problems(str(args.submission), problems)
        return 2
    given = {"n_samples": args.chamfer_samples, "seeds": args.chamfer_seeds}
    cfg = EvalConfig(chamfer=ChamferConfig(**{k: v for k, v in given.items() if v is not None},
                                           component_filter=not args.no_component_filter),
                     states=args.states, limits=Limits(max_mesh_bytes=args.max_mesh_mb,
                                                       max_total_bytes=args.max_total_mb))
    for oid in gt.objects:  # fail early on a bad --states
        from .ground_truth import resolve_states

        resolve_states(gt.meta(oid), args.states)
    results, problems = score_submission(sub, gt, cfg, args.workers)
    if problems:
        print_problems(str(args.submission), problems)
        return 2
    scores = build_scores(
        results, config=cfg.to_dict(), config_hash=cfg.hash(), toolkit_version=_toolkit_version(),
        dataset={"name": gt.name, "version": gt.version, "split": gt.split, "root": str(gt.root)},
        submission={"path": str(args.submission), "sha256": sha256_file(args.submission), "method": sub.method,
                    "dataset": sub.dataset})
    out = args.out or args.submission.parent / "eval"
    files = write_reports(scores, out)
    agg = scores["aggregate"]["overall"]
    print(f"scored {agg['n_objects']} objects ({agg['n_failed_objects']} failed) -> {out}")
    print(Path(files[3]).read_text(encoding="utf-8").split("\n\n## Failures")[0])
    return 0


def _make_gt(args) -> int:
    from .ground_truth import load_ground_truth
    from .gt_submission import make_gt_submission, parse_perturbation

    if args.data is None or args.out is None:
        raise RsartError("--make-gt-submission needs --data ROOT and --out DIR")
    pert = parse_perturbation(args.perturb_joints) if args.perturb_joints else None
    gt = load_ground_truth(args.data, args.split)
    path = make_gt_submission(gt, args.out, args.states, pert, overwrite=args.overwrite)
    print(f"wrote {path} ({len(gt.objects)} objects{', perturbed: ' + args.perturb_joints if pert else ''})")
    return 0


def run(args) -> int:
    if args.perturb_old is not None:
        if args.perturb_joints is not None:
            raise RsartError("give --perturb-joints only (--perturb is its deprecated spelling)")
        print("warning: --perturb is deprecated; use --perturb-joints (camera poses: rsart perturb-poses)",
              file=sys.stderr)
        args.perturb_joints = args.perturb_old
    if args.make_gt_submission:
        return _make_gt(args)
    if args.submission is None:
        raise RsartError("give the SUBMISSION file (or --make-gt-submission)")
    if args.perturb_joints:
        raise RsartError("--perturb-joints only goes with --make-gt-submission")
    if args.validate_only:
        sub, gt, problems = validate(args, check_meshes=True, workers=args.workers)
        if problems:
            print_problems(str(args.submission), problems)
            return 2
        n_null = sum(v is None for v in sub.results.values())
        print(f"{args.submission}: valid ({len(sub.results)} objects, {n_null} null"
              f"{'' if gt is not None else '; structure only: pass --data to check ids and states'})")
        return 0
    if args.data is None:
        raise RsartError("scoring needs --data ROOT (a dataset root or an object folder)")
    return _score(args)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return guarded(lambda: run(args))


if __name__ == "__main__":
    sys.exit(main())
