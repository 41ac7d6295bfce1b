"""benchmarks/pd2gs_suite.py's ablation table: every row must be a valid DiscoveryConfig, since the suite runs
them all by default and a stale row only fails after hours of training."""
from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import pytest

from pd2gs.discovery import DiscoveryConfig

SUITE = Path(__file__).resolve().parents[2] / "benchmarks" / "pd2gs_suite.py"


def _suite():
    spec = importlib.util.spec_from_file_location("pd2gs_suite_bench", SUITE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", list(_suite().ABLATIONS))
def test_every_ablation_row_builds_a_discovery_config(name):
    overrides = _suite().ABLATIONS[name]
    cfg = dataclasses.replace(DiscoveryConfig(), **overrides)
    assert all(getattr(cfg, k) == v for k, v in overrides.items())


def test_a_row_naming_an_unknown_setting_is_caught():
    with pytest.raises(TypeError):
        dataclasses.replace(DiscoveryConfig(), fit_crop=0.1)
