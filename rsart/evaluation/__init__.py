"""Evaluation of submissions (``rsart-eval``): validation, scoring, reports, reference submissions.

    from rsart.evaluation import load_ground_truth, read_submission, score_submission
    gt = load_ground_truth("data/rsart-synth", split="test")
    sub, problems = read_submission("my_method/submission.json", gt)
    results, problems = score_submission(sub, gt)

Contract: DESIGN.md §6.2 (submission) and §6.3 (metrics); docs/evaluation.md.
"""
from __future__ import annotations

import importlib

#: public name -> submodule; imported on first use so ``rsart-eval --help`` stays fast (no trimesh/scipy).
_EXPORTS = {
    "GroundTruth": "ground_truth", "load_ground_truth": "ground_truth", "resolve_states": "ground_truth",
    "Perturbation": "gt_submission", "make_gt_submission": "gt_submission", "parse_perturbation": "gt_submission",
    "EvalConfig": "score", "score_object": "score", "score_submission": "score",
    "Limits": "submission", "Submission": "submission", "load_mesh": "submission", "read_submission": "submission",
}
__all__ = list(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
