"""Evaluation of submissions (``rsart-eval``): validation, scoring, reports, reference submissions.

    from rsart.evaluation import load_ground_truth, read_submission, score_submission
    gt = load_ground_truth("data/rsart-synth", split="test")
    sub, problems = read_submission("my_method/submission.json", gt)
    results, problems = score_submission(sub, gt)

Contract: DESIGN.md §6.2 (submission) and §6.3 (metrics); docs/evaluation.md.
"""
from .ground_truth import GroundTruth, load_ground_truth, resolve_states
from .gt_submission import Perturbation, make_gt_submission, parse_perturbation
from .score import EvalConfig, score_object, score_submission
from .submission import Limits, Submission, load_mesh, read_submission

__all__ = ["GroundTruth", "load_ground_truth", "resolve_states", "Perturbation", "make_gt_submission",
           "parse_perturbation", "EvalConfig", "score_object", "score_submission", "Limits", "Submission",
           "load_mesh", "read_submission"]
