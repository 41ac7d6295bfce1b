"""``rsart validate-submission``: the same checks as ``rsart-eval --validate-only``."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    from ..evaluation.cli import add_eval_arguments

    p = sub.add_parser("validate-submission", help="check a submission (rsart-submission/1) and list every problem",
                       description="Validate a submission file against a dataset (--data): object ids, keys, "
                                   "types, finite numbers, non-zero axes, known states, and every referenced "
                                   "mesh (relative, inside the submission folder, no symlink out, exists, "
                                   "parses, non-empty, within the size limits). Prints every problem with its "
                                   "JSON path; exit 0 when valid, 2 otherwise. Same as rsart-eval --validate-only.")
    add_eval_arguments(p, submission_required=True)
    p.add_argument("--workers", type=int, default=None, help="processes for parsing meshes (default: all cores)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from ..evaluation.cli import print_problems, validate

    sub, gt, problems = validate(args, check_meshes=True, workers=args.workers)
    if problems:
        print_problems(str(args.submission), problems)
        return 2
    n_null = sum(v is None for v in sub.results.values())
    print(f"{args.submission}: valid ({len(sub.results)} objects, {n_null} null)")
    return 0
