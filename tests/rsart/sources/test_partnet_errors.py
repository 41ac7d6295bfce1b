"""Broken PartNet-Mobility folders and bad `rsart convert partnet-mobility` usage: exit 2, a message
naming the file/option, no traceback, no half-written output (a real object copied to tmp, then broken)."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from rsart.cli import main

RES = ["--resolution", "32", "-q"]


def _break(d: Path, case: str) -> str:
    """Break the copied object folder ``d``; returns the fragment the error must contain."""
    if case == "no_urdf":
        (d / "mobility.urdf").unlink()
        return "mobility.urdf: file not found"
    if case == "meta_bad_json":
        (d / "meta.json").write_text('{"model_cat": "Faucet",')
        return "meta.json: invalid JSON"
    if case == "meta_no_category":
        (d / "meta.json").write_text('{"anno_id": "148"}')
        return "meta.json: model_cat"
    if case == "meta_not_object":
        (d / "meta.json").write_text("[1, 2]")
        return "meta.json: expected a JSON object"
    if case == "meta_nan":
        (d / "meta.json").write_text('{"model_cat": "Faucet", "x": NaN}')
        return "meta.json"
    if case == "semantics_bad_line":
        (d / "semantics.txt").write_text("link_0 hinge\n")
        return "semantics.txt: line 1"
    if case == "mobility_not_list":
        (d / "mobility_v2.json").write_text('{"id": 0}')
        return "mobility_v2.json: expected a list"
    if case == "mobility_bad_entry":
        (d / "mobility_v2.json").write_text('[{"id": "zero"}]')
        return "mobility_v2.json: [0]"
    if case == "missing_mesh":
        for f in (d / "textured_objs").glob("*.obj"):
            f.unlink()
        return "not found"
    if case == "urdf_dtd":
        (d / "mobility.urdf").write_text('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
                                         '<robot name="&x;"><link name="a"/></robot>')
        return "DTD"
    if case == "urdf_truncated":
        text = (d / "mobility.urdf").read_text()
        (d / "mobility.urdf").write_text(text[: len(text) // 2])
        return "not well-formed XML"
    raise AssertionError(case)


CASES = ["no_urdf", "meta_bad_json", "meta_no_category", "meta_not_object", "meta_nan", "semantics_bad_line",
         "mobility_not_list", "mobility_bad_entry", "missing_mesh", "urdf_dtd", "urdf_truncated"]


@pytest.mark.parametrize("case", CASES)
def test_broken_partnet_folder(case, partnet_root, tmp_path, capsys):
    d = tmp_path / "148"
    shutil.copytree(partnet_root / "148", d)  # a private copy in tmp, broken below
    fragment = _break(d, case)
    out = tmp_path / "out" / "pm-148"
    assert main(["convert", "partnet-mobility", str(d), "--out", str(out), *RES]) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err, err
    assert str(d) in err, err
    assert not out.exists() and not (out.parent.exists() and any(out.parent.iterdir()))


@pytest.mark.parametrize("argv,fragment", [
    (["--root", "{root}", "--split", "no-such-split"], "unknown split 'no-such-split'"),
    (["--root", "{tmp}/nowhere", "--ids", "148"], "nowhere: not a folder"),
    (["{root}/148", "--root", "{root}", "--ids", "148"], "either PM_OBJECT_DIR or --root"),
    (["--ids", "148"], "need --root"),
    (["{tmp}/not-an-object"], "not-an-object: not a folder"),
    ([], "give PM_OBJECT_DIR"),
    (["--root", "{root}"], "--root needs --ids"),
    (["--root", "{root}", "--ids", "../148"], "converted 0/1"),
    (["{root}/148", "--metric-scale", "-1"], "--metric-scale must be a positive finite number"),
    (["{root}/148", "--resolution", "4"], "--resolution must be within 16..2048"),
])
def test_bad_usage(argv, fragment, partnet_root, tmp_path, capsys):
    argv = [a.replace("{root}", str(partnet_root)).replace("{tmp}", str(tmp_path)) for a in argv]
    code = main(["convert", "partnet-mobility", *RES, *argv, "--out", str(tmp_path / "o")])
    cap = capsys.readouterr()
    assert code == 2
    assert fragment in cap.err + cap.out and "Traceback" not in cap.err
    assert not (tmp_path / "o" / "pm-148").exists()


@pytest.mark.parametrize("entry", [
    '{"id": 0, "parent": 1, "joint": "hinge", "jointData": {"axis": {"origin": [0, 0, 0], "direction": [0, 1e999, 0]},'
    ' "limit": {"a": 1e999, "b": 0}}}',
    '{"id": 0, "parent": 1, "joint": "hinge", "jointData": {"axis": "up", "limit": [1, 2]}}',
    '{"id": 0, "parent": 1, "joint": "hinge", "jointData": {"axis": {"direction": [0, 0, 0]}, "limit": {}}}',
])
def test_odd_mobility_v2_entry_is_recorded_not_fatal(entry, partnet_root, tmp_path, capsys):
    """mobility_v2.json is only cross-checked: a nonsensical entry is noted, the URDF is converted."""
    d = tmp_path / "148"
    shutil.copytree(partnet_root / "148", d)
    (d / "mobility_v2.json").write_text(f'[{entry}, {{"id": 1, "parent": -1, "joint": "static"}}]')
    out = tmp_path / "o"
    assert main(["convert", "partnet-mobility", str(d), "--out", str(out), *RES]) == 0
    from rsart.format import read_meta

    meta = read_meta(out)
    assert meta.joints[0].extra["mobility_v2"]["agrees"] is False
    assert any("disagrees" in n for n in meta.extra["conversion_notes"])
