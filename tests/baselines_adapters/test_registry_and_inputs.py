"""Built-in registry (the entry points the lead adds to pyproject.toml resolve) and bad run folders."""
from __future__ import annotations

import json

import pytest

from baselines_adapters import BUILTIN, available, get_adapter
from baselines_adapters.registry import instantiate
from rsart.errors import RsartError
from tests.baselines_adapters.ba_helpers import play_artgs, play_dtart


def test_builtin_entry_point_values_resolve_to_named_adapters():
    import importlib

    for name, ref in BUILTIN.items():
        mod, attr = ref.split(":")
        ad = instantiate(getattr(importlib.import_module(mod), attr))
        assert ad.name == name and ad.protocol in ("two-state", "single-joint") and ad.description
    assert set(available(include_entry_points=False)) == set(BUILTIN)
    with pytest.raises(RsartError, match="available: .*artgs"):
        get_adapter("nope")
    with pytest.raises(RsartError, match="not an adapter"):
        instantiate(42)


def test_protocol_per_family():
    assert get_adapter("paris").protocol == get_adapter("articulatedgs").protocol == "single-joint"
    assert {get_adapter(n).protocol for n in ("dtart", "artgs", "reartgs", "reartgspp")} == {"two-state"}


@pytest.fixture(scope="module")
def exports(objects, tmp_path_factory):
    root = tmp_path_factory.mktemp("exp")
    get_adapter("dtart").export(objects["cabinet/two-state"], root / "dtart")
    get_adapter("artgs").export(objects["cabinet/two-state"], root / "artgs")
    return root


def test_dtart_bad_run_folders(exports, objects, tmp_path):
    ad, obj = get_adapter("dtart"), objects["cabinet/two-state"]
    with pytest.raises(RsartError, match="no DTArt results"):
        ad.import_run(tmp_path, obj, tmp_path / "s.json")
    run = play_dtart(exports / "dtart", tmp_path / "r")
    f = run / "results" / "step_0004000" / "init_p01_motion.json"
    f.write_text(json.dumps([{"rotation": [[1, 0, 0]], "translation": [0, 0, 0]}] * 2))
    with pytest.raises(RsartError, match="entry 0: needs rotation"):
        ad.import_run(run, obj, tmp_path / "s.json")
    f.write_text(json.dumps([]))
    with pytest.raises(RsartError, match="list of 2 joints"):
        ad.import_run(run, obj, tmp_path / "s.json")
    (run / "results" / "step_0004000" / "init_part_1.obj").write_text("this is not a mesh\n")
    with pytest.raises(RsartError):
        ad.import_run(run, obj, tmp_path / "s.json")
    assert not (tmp_path / "s.json").exists()  # nothing written on failure


def test_artgs_bad_run_folders(exports, objects, tmp_path):
    ad, obj = get_adapter("artgs"), objects["cabinet/two-state"]
    run = play_artgs(exports / "artgs", tmp_path / "m")
    ji = run / "train" / "ours_20000" / "joint_info.json"
    info = json.loads(ji.read_text())
    info[1]["joint"] = "ball"
    ji.write_text(json.dumps(info))
    with pytest.raises(RsartError, match="not hinge or slider"):
        ad.import_run(run, obj, tmp_path / "s.json")
    info[1]["joint"] = "hinge"
    info[1]["jointData"]["axis"]["direction"] = [0, 0, 0]
    ji.write_text(json.dumps(info))
    with pytest.raises(RsartError, match="zero length"):
        ad.import_run(run, obj, tmp_path / "s.json")
    info[1]["jointData"]["axis"]["direction"] = [0, 1, 0]
    ji.write_text(json.dumps(info))
    (run / "train" / "ours_20000" / "meshes" / "end_1.ply").unlink()
    rep = ad.import_run(run, obj, tmp_path / "s.json")  # a slot without its end mesh is left out, noted
    assert rep.parts == ["static", "part_2"] and any("part_1" in n and "left out" in n for n in rep.notes)


def test_submission_file_is_not_clobbered(objects, exports, tmp_path):
    sub = tmp_path / "s.json"
    sub.write_text('{"something": "else"}')
    with pytest.raises(RsartError, match="refusing to overwrite"):
        get_adapter("artgs").import_run(play_artgs(exports / "artgs", tmp_path / "m"), objects["cabinet/two-state"], sub)
    assert json.loads(sub.read_text()) == {"something": "else"}
