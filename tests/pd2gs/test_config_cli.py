"""pd2gs configs generate their command line: choices, defaults and help come from the fields."""
import dataclasses
import subprocess
import sys

import pytest

from pd2gs.cli import _parser
from pd2gs.config import DeformConfig, TrainConfig
from pd2gs.config_cli import ConfigError, choices, field_docs, overrides
from pd2gs.discovery.config import DiscoveryConfig, VLMConfig
from rsart.errors import RsartError

CONFIGS = (TrainConfig, DeformConfig, DiscoveryConfig, VLMConfig)


@pytest.mark.parametrize("cls", CONFIGS, ids=lambda c: c.__name__)
def test_every_field_has_a_docstring(cls):
    docs = field_docs(cls)
    missing = [f.name for f in dataclasses.fields(cls) if not docs.get(f.name)]
    assert missing == []


@pytest.mark.parametrize("cls,name,bad", [(TrainConfig, "backend", "cuda"), (TrainConfig, "init", "sphere"),
                                          (DeformConfig, "activation", "gelu"), (DiscoveryConfig, "counter", "llm"),
                                          (DiscoveryConfig, "joint_rule", "ols")])
def test_a_choice_outside_its_literal_is_refused_naming_the_field(cls, name, bad):
    with pytest.raises(ConfigError, match=rf"{cls.__name__}\.{name}='{bad}'") as e:
        cls(**{name: bad})
    assert isinstance(e.value, RsartError) and isinstance(e.value, ValueError)


def test_cli_choices_and_defaults_are_the_fields():
    ap = _parser()
    sub = next(a for a in ap._actions if a.dest == "cmd").choices
    opts = {a.option_strings[0]: a for a in sub["run"]._actions if a.option_strings}
    assert tuple(opts["--counter"].choices) == choices(DiscoveryConfig, "counter")
    assert tuple(opts["--joint-rule"].choices) == choices(DiscoveryConfig, "joint_rule")
    assert f"(default {DiscoveryConfig().joint_rule})" in opts["--joint-rule"].help
    topts = {a.option_strings[0]: a for a in sub["train"]._actions if a.option_strings}
    assert tuple(topts["--backend"].choices) == choices(TrainConfig, "backend")
    args = ap.parse_args(["run", "--data", "d", "--out", "o", "--no-refine", "--joint-rule", "paper", "--iters", "7"])
    assert overrides(args, DiscoveryConfig) == {"refine": False, "joint_rule": "paper"}
    assert overrides(args, TrainConfig) == {"iters": 7}
    args = ap.parse_args(["run", "--data", "d", "--out", "o"])
    assert overrides(args, DiscoveryConfig) == {} and overrides(args, TrainConfig) == {}


def test_invalid_values_exit_2_without_a_traceback(tmp_path):
    for argv in (["train", str(tmp_path), "--out", str(tmp_path / "r"), "--iters", "0"],
                 ["run", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--n-states", "1"],
                 ["run", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--canonical", "widest,end"]):
        r = subprocess.run([sys.executable, "-m", "pd2gs.cli", *argv], capture_output=True, text=True)
        assert r.returncode == 2 and "Traceback" not in r.stderr and "pd2gs: error:" in r.stderr, r.stderr
        if "--canonical" in argv:
            assert "canonical" in r.stderr, r.stderr
