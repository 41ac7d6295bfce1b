"""Malformed submissions: each gets a specific message with its JSON path, exit 2, no traceback."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from rsart.evaluation.cli import main

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)

LID = ("results", "cabinet-0000", "parts", "lid")


def _get(data, path):
    for k in path:
        data = data[k]
    return data


def set_text(text):
    def f(d, data):
        (d / "submission.json").write_text(text)
        return "raw"
    return f


def edit(fn):
    def f(d, data):
        fn(d, data)
    return f


def _mesh(data, part="lid", sid="m0"):
    return _get(data, ("results", "cabinet-0000", "parts", part, "meshes"))


def _set_mesh(d, data, rel, part="lid", sid="m0"):
    _mesh(data, part)[sid] = rel


def _write(d, rel, content: bytes):
    (d / rel).parent.mkdir(parents=True, exist_ok=True)
    (d / rel).write_bytes(content)


def _symlink_out(d, data):
    outside = d.parent / "outside.ply"
    outside.write_bytes((d / _mesh(data)["m0"]).read_bytes())
    (d / "link.ply").symlink_to(outside)
    _set_mesh(d, data, "link.ply")


def _garbage_ply(d, data):
    _write(d, "bad.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nend_header\n\x00\x01")
    _set_mesh(d, data, "bad.ply")


def _points_only(d, data):
    _write(d, "pts.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                         b"property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n")
    _set_mesh(d, data, "pts.ply")


def _dir_as_mesh(d, data):
    (d / "adir.ply").mkdir()
    _set_mesh(d, data, "adir.ply")


def _jset(key, value):
    def f(d, data):
        _get(data, LID)["joint"][key] = value
    return f


CASES = {
    "bad_json": (set_text('{"format": "rsart-submission/1",'), "invalid JSON at line 1"),
    "nan_constant": (set_text('{"format": NaN}'), "non-finite number NaN"),
    "top_level_list": (set_text("[1, 2]"), "must be a JSON object, got a list"),
    "duplicate_key": (set_text('{"format": "rsart-submission/1", "format": "x", "method": {"name": "m"}, '
                               '"dataset": {}, "results": {}}'), "duplicate key 'format'"),
    "wrong_format": (edit(lambda d, s: s.update(format="rsart-submission/0")), "format: 'rsart-submission/0' is not"),
    "unknown_top_key": (edit(lambda d, s: s.update(extra=1)), "extra: unknown key"),
    "missing_method": (edit(lambda d, s: s.pop("method")), "method: missing"),
    "method_without_name": (edit(lambda d, s: s.update(method={"version": "1"})), "method.name: missing"),
    "dataset_mismatch": (edit(lambda d, s: s.update(dataset={"name": "other"})), "dataset.name: 'other' does not match"),
    "missing_object": (edit(lambda d, s: s["results"].pop("lamp-0000")), "results.lamp-0000: missing object"),
    "unknown_object": (edit(lambda d, s: s["results"].update(nope=None)), "results.nope: unknown object id"),
    "object_is_list": (edit(lambda d, s: s["results"].update({"lamp-0000": []})),
                       "results.lamp-0000: expected an object (or null for a failure), got a list"),
    "no_static_part": (edit(lambda d, s: s["results"]["cabinet-0000"]["parts"].pop("static")), "no 'static' part"),
    "unknown_part_key": (edit(lambda d, s: _get(s, LID).update(color="red")), "parts.lid.color: unknown key"),
    "movable_without_joint": (edit(lambda d, s: _get(s, LID).pop("joint")), "parts.lid.joint: missing"),
    "static_with_joint": (edit(lambda d, s: s["results"]["cabinet-0000"]["parts"]["static"].update(
        joint=_get(s, LID)["joint"])), "parts.static.joint: the static part has no joint"),
    "bad_joint_type": (edit(_jset("type", "hinge")), "joint.type: 'hinge' is not one of"),
    "unknown_joint_key": (edit(_jset("pivot", [0, 0, 0])), "joint.pivot: unknown key"),
    "axis_wrong_length": (edit(_jset("axis", [0, 1])), "joint.axis: expected a list of 3 numbers"),
    "axis_not_numbers": (edit(_jset("axis", [0, "1", 0])), "joint.axis: expected 3 numbers"),
    "axis_zero": (edit(_jset("axis", [0, 0, 0])), "joint.axis: zero-length vector"),
    "axis_overflow_inf": (edit(lambda d, s: None), "joint.axis: non-finite number"),
    "revolute_without_origin": (edit(lambda d, s: _get(s, LID)["joint"].pop("origin")),
                                "joint.origin: missing (a revolute joint needs a point"),
    "value_unknown_state": (edit(lambda d, s: _get(s, LID)["joint"]["values"].update(m9=0.1)),
                            "joint.values.m9: unknown state 'm9'"),
    "value_boolean": (edit(lambda d, s: _get(s, LID)["joint"]["values"].update(m1=True)),
                      "joint.values.m1: expected a number, got a boolean"),
    "value_missing_end": (edit(lambda d, s: _get(s, LID)["joint"]["values"].pop("m3")),
                          "no value for the end state 'm3'"),
    "mesh_unknown_state": (edit(lambda d, s: _mesh(s).update(m9=_mesh(s)["m0"])), "meshes.m9: unknown state"),
    "mesh_absolute": (edit(lambda d, s: _set_mesh(d, s, str(d / _mesh(s)["m0"]))), "is absolute"),
    "mesh_escapes": (edit(lambda d, s: _set_mesh(d, s, "../outside.ply")), "escapes the submission folder"),
    "mesh_symlink_out": (edit(_symlink_out), "symlink (or passes through one) leading out"),
    "mesh_missing": (edit(lambda d, s: _set_mesh(d, s, "nothere.ply")), "'nothere.ply' is missing"),
    "mesh_not_a_string": (edit(lambda d, s: _set_mesh(d, s, 3)), "expected a relative file path (string), got a number"),
    "mesh_wrong_kind": (edit(lambda d, s: (_write(d, "m.txt", b"hello"), _set_mesh(d, s, "m.txt"))),
                        "is not a supported file kind"),
    "mesh_content_mismatch": (edit(lambda d, s: (_write(d, "fake.ply", b"hello world"), _set_mesh(d, s, "fake.ply"))),
                              "content does not match the extension"),
    "mesh_empty": (edit(lambda d, s: (_write(d, "empty.ply", b""), _set_mesh(d, s, "empty.ply"))), "is empty (0 bytes)"),
    "mesh_is_directory": (edit(_dir_as_mesh), "is not a regular file"),
    "mesh_too_large": (edit(lambda d, s: None), "over the per-file limit"),
    "mesh_unparseable": (edit(_garbage_ply), "cannot be parsed as PLY"),
    "mesh_without_triangles": (edit(_points_only), "contains no triangles"),
    "render_view_id_escapes": (edit(lambda d, s: s["results"]["cabinet-0000"].update(
        renders={"m0": {"../../x": "r.png"}})), "view id must be letters"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_malformed_submission(name, dataset, sub_copy, capsys):
    d, data, save = sub_copy
    fn, message = CASES[name]
    raw = fn(d, data)
    if name == "axis_overflow_inf":
        text = (d / "submission.json").read_text()
        import json

        s = json.dumps(data).replace('"axis": [0.0, 1.0, 0.0]', '"axis": [0.0, 1e400, 0.0]', 1)
        assert s != json.dumps(data)
        (d / "submission.json").write_text(s)
    elif raw != "raw":
        save()
    args = [str(d / "submission.json"), "--data", str(dataset), "--validate-only", "--workers", "1"]
    if name == "mesh_too_large":
        args += ["--max-mesh-mb", "0.0001"]
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2, err
    assert message in err, err
    assert "Traceback" not in err


def test_at_least_25_cases():
    assert len(CASES) >= 25


def test_every_problem_is_listed(dataset, sub_copy, capsys):
    d, data, save = sub_copy
    data["results"].pop("lamp-0000")
    data["results"].pop("cabinet-0001")
    _get(data, LID)["joint"]["axis"] = [0, 0, 0]
    _set_mesh(d, data, "/etc/passwd")
    save()
    assert main([str(d / "submission.json"), "--data", str(dataset), "--validate-only"]) == 2
    err = capsys.readouterr().err
    assert "4 problems" in err
    for m in ("results.lamp-0000: missing object", "results.cabinet-0001: missing object", "zero-length vector",
              "is absolute"):
        assert m in err


def test_scoring_an_invalid_submission_exits_2_without_reading_outside(dataset, sub_copy, capsys, tmp_path):
    d, data, save = sub_copy
    _set_mesh(d, data, "../../../../../../etc/hostname")
    save()
    out = tmp_path / "out"
    assert main([str(d / "submission.json"), "--data", str(dataset), "--out", str(out), "--workers", "1"]) == 2
    assert "escapes the submission folder" in capsys.readouterr().err
    assert not out.exists()


def test_unparseable_mesh_found_while_scoring_exits_2(dataset, sub_copy, capsys, tmp_path):
    d, data, save = sub_copy
    _garbage_ply(d, data)
    save()
    out = tmp_path / "out"
    assert main([str(d / "submission.json"), "--data", str(dataset), "--out", str(out), "--workers", "1",
                 "--chamfer-samples", "500", "--chamfer-seeds", "0"]) == 2
    err = capsys.readouterr().err
    assert "results.cabinet-0000.parts.lid.meshes.m0: bad.ply: cannot be parsed as PLY" in err
    assert not out.exists()


def test_valid_submission_passes(dataset, gt_submission_dir, capsys):
    assert main([str(gt_submission_dir / "submission.json"), "--data", str(dataset), "--validate-only",
                 "--workers", "1"]) == 0
    assert "valid (3 objects, 0 null)" in capsys.readouterr().out


def test_bad_usage_exits_2(dataset, gt_submission_dir, capsys):
    assert main([str(gt_submission_dir / "submission.json")]) == 2  # no --data
    assert "needs --data" in capsys.readouterr().err
    assert main([str(gt_submission_dir / "submission.json"), "--data", str(dataset), "--split", "nope"]) == 2
    assert "no split 'nope'" in capsys.readouterr().err
    assert main([str(gt_submission_dir / "submission.json"), "--data", str(dataset / "missing")]) == 2
    assert main(["--make-gt-submission", "--data", str(dataset), "--out", "x", "--perturb", "axis=abc"]) == 2
    assert "axis='abc' is not a number" in capsys.readouterr().err
