"""Pinned reference scores: any change to what the metrics compute shows up here.

The reference set (tests/data/reference, README.md there) holds two generated objects and three
submissions (ground truth, perturbed ground truth, a PD²GS output) with every per-object number of
their scores.json pinned in expected_scores.json. A number that moves by more than its tolerance fails
(Chamfer: the standard error of the 3-seed mean; every other number: 1e-9). An intended metric change
bumps SCORER_VERSION, regenerates the expected scores (regenerate.py) and adds a CHANGELOG.md entry.
"""
from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

from rsart.evaluation.version import SCORER_VERSION

REPO = Path(__file__).resolve().parents[3]
REF = REPO / "tests" / "data" / "reference"


def _regenerate():
    spec = importlib.util.spec_from_file_location("reference_regenerate", REF / "regenerate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


EXPECTED = json.loads((REF / "expected_scores.json").read_text())


@pytest.mark.core
def test_scorer_version_is_pinned_and_in_changelog():
    """The pinned scores belong to this scorer version, and CHANGELOG.md's metrics section names it."""
    assert EXPECTED["scorer_version"] == SCORER_VERSION, (
        "SCORER_VERSION changed: regenerate tests/data/reference/expected_scores.json and add a CHANGELOG entry")
    text = (REPO / "CHANGELOG.md").read_text()
    metrics = text.split("## Metrics", 1)[1].split("\n## ", 1)[0]
    assert re.search(rf"^### Scorer {re.escape(SCORER_VERSION)}\b", metrics, re.M), metrics[:400]


@pytest.mark.core
@pytest.mark.parametrize("name", ["gt", "perturbed", "pd2gs"])
def test_reference_scores_do_not_move(name, tmp_path):
    reg = _regenerate()
    scores = reg.score(name, out=tmp_path)
    assert scores["toolkit"]["scorer_version"] == SCORER_VERSION
    got = reg.numbers(scores["objects"])
    want = EXPECTED["submissions"][name]
    assert set(got) == set(want), {"new": sorted(set(got) - set(want)), "gone": sorted(set(want) - set(got))}
    moved = {p: f"{got[p]!r} vs pinned {w['value']!r} (tol {w['tol']:.3g})"
             for p, w in want.items() if not abs(got[p] - w["value"]) <= w["tol"]}
    assert not moved, f"{len(moved)} of {len(want)} numbers moved: " + json.dumps(moved, indent=1)


@pytest.mark.core
def test_reference_set_is_meaningful():
    """The three submissions differ where they should: GT at the sampling floor with exact joints, the
    perturbed one off by its perturbation (5° axes), PD²GS worse than GT in Chamfer."""
    gt, pert, pd = (EXPECTED["submissions"][n] for n in ("gt", "perturbed", "pd2gs"))
    for oid in ("drawer-1p-0000", "box-1p-0000"):
        assert gt[f"{oid}/metrics/axis_ang"]["value"] == pytest.approx(0, abs=1e-6)
        assert pert[f"{oid}/metrics/axis_ang"]["value"] == pytest.approx(5.0, abs=1e-6)
        assert pd[f"{oid}/metrics/cd_w"]["value"] > gt[f"{oid}/metrics/cd_w"]["value"]
    tols = [w["tol"] for w in gt.values() if w["tol"] > 1e-9]
    assert tols, "Chamfer numbers must carry seed-spread tolerances"
