"""benchmarks/pd2gs_suite.py's ablation table: every row must be a valid DiscoveryConfig, since the suite runs
them all by default and a stale row only fails after hours of training."""
from __future__ import annotations

import dataclasses

import pytest

from pd2gs.discovery import DiscoveryConfig
from tests.benchmarks.bench_helpers import load


def _suite():
    return load("pd2gs_suite.py")


@pytest.mark.parametrize("name", list(_suite().ABLATIONS))
def test_every_ablation_row_builds_a_discovery_config(name):
    overrides = _suite().ABLATIONS[name]
    cfg = dataclasses.replace(DiscoveryConfig(), **overrides)
    assert all(getattr(cfg, k) == v for k, v in overrides.items())


def test_a_row_naming_an_unknown_setting_is_caught():
    with pytest.raises(TypeError):
        dataclasses.replace(DiscoveryConfig(), fit_crop=0.1)
