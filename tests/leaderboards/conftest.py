"""Session fixtures: one tiny generated dataset, its GT / perturbed / partly-failed submissions, scored once."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from lb_helpers import build_dataset, make_submission, score_many  # noqa: E402


@pytest.fixture(scope="session")
def lb_root(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("lb")


@pytest.fixture(scope="session")
def dataset(lb_root) -> Path:
    return build_dataset(lb_root / "data")


@pytest.fixture(scope="session")
def one_object(lb_root) -> Path:
    """A single-object dataset for the server tests (fast scoring)."""
    return build_dataset(lb_root / "data1", objects=(("drawer", 0),))


@pytest.fixture(scope="session")
def scored(lb_root, dataset) -> dict[str, Path]:
    """rsart-eval output folders: gt, perturbed (axis 5°), partly failed (one null object)."""
    gt = make_submission(dataset, lb_root / "sub_gt")
    pert = make_submission(dataset, lb_root / "sub_pert", perturb="axis=5deg,pivot=0.02,seed=0", method="perturbed")
    fail = make_submission(dataset, lb_root / "sub_fail", method="half-failed", null=("door-0001",))
    outs = score_many([(gt, dataset, lb_root / "eval_gt"), (pert, dataset, lb_root / "eval_pert"),
                       (fail, dataset, lb_root / "eval_fail")])
    return dict(zip(("gt", "perturbed", "failed"), outs))

