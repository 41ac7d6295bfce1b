"""`rsart convert urdf` on good and bad URDF files: a clear error (exit 2, file/element named, no
traceback, nothing left behind) for every malformed or hostile input; helper-link folding; scaling."""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from rsart.cli import main
from rsart.errors import RsartError
from rsart.format import Joint, read_meta
from rsart.kinematics import Twin, TwinPart
from rsart.sources.urdf_twin import WatertightConfig, convert_urdf, fold_helper_parts, watertight_copy

FAST = ["--resolution", "48", "-q"]
LINK = '<link name="{n}"><visual><geometry><mesh filename="{m}"/></geometry></visual></link>'


def _box_obj(path: Path, extents=(0.2, 0.2, 0.2), center=(0, 0, 0)) -> None:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(center)
    path.write_text(trimesh.exchange.obj.export_obj(m))


def _urdf(links: list[str], joints: list[str], name: str = "t") -> str:
    return f'<?xml version="1.0"?>\n<robot name="{name}">\n' + "\n".join(links + joints) + "\n</robot>\n"


def _joint(name, typ, parent, child, xyz="0 0 0", axis="0 0 1", limit='<limit lower="0" upper="1"/>'):
    ax = f'<axis xyz="{axis}"/>' if axis is not None else ""
    return (f'<joint name="{name}" type="{typ}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}"/>{ax}{limit}</joint>')


GOOD_LINKS = [LINK.format(n="body", m="body.obj"), LINK.format(n="lid", m="lid.obj")]


def _good(**kw) -> str:
    return _urdf(GOOD_LINKS, [_joint("hinge", kw.get("typ", "revolute"), "body", "lid", kw.get("xyz", "0 0.1 0.1"),
                                     kw.get("axis", "1 0 0"), kw.get("limit", '<limit lower="0" upper="1.5"/>'))])


@pytest.fixture
def urdf_dir(tmp_path) -> Path:
    d = tmp_path / "src"
    d.mkdir()
    _box_obj(d / "body.obj", (0.2, 0.2, 0.2), (0, 0, 0))
    _box_obj(d / "lid.obj", (0.2, 0.2, 0.02), (0, 0, 0.11))
    return d


# name -> (urdf text, fragment the error message must contain). {ext} = a file outside the folder.
BAD = {
    "not_xml": ("this is not xml <robot", "not well-formed XML"),
    "billion_laughs": ('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;">'
                       '<!ENTITY lol3 "&lol2;&lol2;&lol2;">]><robot name="&lol3;"><link name="a"/></robot>', "DTD"),
    "external_entity": ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file://{ext}">]>'
                        '<robot name="&x;"><link name="a"/></robot>', "DTD"),
    "empty_file": ("", "not well-formed XML"),
    "no_links": ('<robot name="r"></robot>', "no links"),
    "missing_mesh": (_urdf([LINK.format(n="body", m="nope.obj")], []),
                     "link[body].visual[0]: mesh file 'nope.obj' not found"),
    "mesh_escapes": (_urdf([LINK.format(n="body", m="../outside.obj")], []), "leaves the URDF folder"),
    "mesh_absolute": (_urdf([LINK.format(n="body", m="{ext}")], []), "absolute mesh path"),
    "mesh_symlink_out": (_urdf([LINK.format(n="body", m="link.obj")], []), "leaves the URDF folder"),
    "corrupt_mesh": (_urdf([LINK.format(n="body", m="corrupt.obj")], []), "corrupt.obj: cannot read mesh"),
    "unknown_joint_type": (_good(typ="ball"), "joint[hinge]: unsupported joint type 'ball'"),
    "floating_joint": (_good(typ="floating"), "unsupported joint type 'floating'"),
    "cycle": (_urdf(GOOD_LINKS, [_joint("a", "revolute", "body", "lid"), _joint("b", "revolute", "lid", "body")]),
              "cycle"),
    "two_roots": (_urdf(GOOD_LINKS + [LINK.format(n="other", m="lid.obj")], [_joint("a", "revolute", "body", "lid")]),
                  "exactly one root link"),
    "nan_origin": (_good(xyz="nan 0 0"), "joint[hinge].origin"),
    "inf_axis": (_good(axis="inf 0 0"), "joint[hinge].axis"),
    "zero_axis": (_good(axis="0 0 0"), "joint[hinge].axis: zero-length vector"),
    "nan_limit": (_good(limit='<limit lower="nan" upper="1"/>'), "joint[hinge].limit"),
    "lower_gt_upper": (_good(limit='<limit lower="2" upper="1"/>'), "joint[hinge].limit: lower 2.0 > upper 1.0"),
    "prismatic_no_limit": (_good(typ="prismatic", limit=""), "joint[hinge].limit"),
    "unknown_link": (_urdf(GOOD_LINKS, [_joint("a", "revolute", "body", "ghost")]), "unknown link 'ghost'"),
    "duplicate_link": (_urdf(GOOD_LINKS + [LINK.format(n="lid", m="lid.obj")],
                             [_joint("a", "revolute", "body", "lid")]),
                       "duplicate link name"),
    "two_parents": (_urdf(GOOD_LINKS + [LINK.format(n="c", m="lid.obj")],
                          [_joint("a", "revolute", "body", "lid"), _joint("b", "revolute", "c", "lid")]),
                    "child of two joints"),
    "no_geometry_at_all": ('<robot name="r"><link name="a"/></robot>', "parts without any geometry"),
    "helper_two_children": (_urdf(GOOD_LINKS + ['<link name="h"/>', LINK.format(n="c", m="lid.obj")],
                                  [_joint("a", "prismatic", "body", "h"), _joint("b", "revolute", "h", "lid"),
                                   _joint("c", "revolute", "h", "c")]), "no geometry but 2 child joints"),
    "bad_number": (_good(xyz="1 two 3"), "not a valid URDF"),
    "nan_vertex": (_urdf([LINK.format(n="body", m="nan.obj")], []), "part 'base': mesh has non-finite vertex"),
    "zero_area_mesh": (_urdf([LINK.format(n="body", m="flat.obj")], []), "part 'base': mesh has no surface"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_urdf_is_refused_cleanly(case, urdf_dir, tmp_path, capsys):
    text, fragment = BAD[case]
    outside = tmp_path / "secret.obj"
    _box_obj(outside)
    (urdf_dir / "corrupt.obj").write_bytes(b"v 1 2\nf 1 2 3 4 5\n\x00\xff garbage")
    (urdf_dir / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (urdf_dir / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    os.symlink(outside, urdf_dir / "link.obj")
    path = urdf_dir / "robot.urdf"
    path.write_text(text.replace("{ext}", str(outside)))
    out = tmp_path / "out" / "obj"
    code = main(["convert", "urdf", str(path), "--out", str(out), *FAST])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    assert str(path) in err or case == "corrupt_mesh", err  # a broken mesh is named itself
    assert fragment in err, err
    assert not out.exists()
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())  # no half-written folder


def test_cli_errors_have_no_traceback_in_a_real_process(urdf_dir, tmp_path):
    path = urdf_dir / "robot.urdf"
    path.write_text(BAD["billion_laughs"][0])
    r = subprocess.run([sys.executable, "-m", "rsart", "convert", "urdf", str(path), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "robot.urdf" in r.stderr and "DTD" in r.stderr
    r = subprocess.run([sys.executable, "-m", "rsart", "convert", "urdf", str(tmp_path / "nope.urdf"),
                        "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "nope.urdf" in r.stderr and "Traceback" not in r.stderr


def test_existing_output_is_not_replaced_without_overwrite(urdf_dir, tmp_path, capsys):
    (urdf_dir / "robot.urdf").write_text(_good())
    out = tmp_path / "obj"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["convert", "urdf", str(urdf_dir / "robot.urdf"), "--out", str(out), *FAST]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (out / "keep.txt").read_text() == "mine"


def test_good_urdf_converts_with_joint_in_world_frame(urdf_dir, tmp_path):
    (urdf_dir / "robot.urdf").write_text(_good())
    out = tmp_path / "obj"
    assert main(["convert", "urdf", str(urdf_dir / "robot.urdf"), "--out", str(out), "--category", "box", *FAST]) == 0
    meta = read_meta(out)
    assert meta.units == "m" and meta.category == "box" and meta.source == {"kind": "urdf", "id": "robot.urdf"}
    (j,) = meta.joints
    np.testing.assert_allclose(j.axis, [1, 0, 0])
    np.testing.assert_allclose(j.origin, [0, 0.1, 0.1])
    assert j.limits == (0.0, 1.5)
    for p in meta.parts:
        m = trimesh.load(out / p.mesh, process=False)
        assert m.is_watertight
    # the body box is closed already: kept exactly
    assert meta.parts[0].extra["watertight"]["method"] == "closed-as-is"


def test_scale_converts_units_and_prismatic_limits(urdf_dir, tmp_path):
    (urdf_dir / "robot.urdf").write_text(_good(typ="prismatic", limit='<limit lower="0" upper="0.5"/>'))
    meta = convert_urdf(urdf_dir / "robot.urdf", tmp_path / "o", units="scene", scale=2.0,
                        watertight=WatertightConfig(resolution=48))
    assert meta.units == "m" and meta.extra["scale_to_metres"] == 2.0
    assert meta.joints[0].limits == (0.0, 1.0)
    np.testing.assert_allclose(meta.joints[0].origin, [0, 0.2, 0.2])
    body = trimesh.load(tmp_path / "o" / meta.parts[0].mesh, process=False)
    np.testing.assert_allclose(body.extents, [0.4, 0.4, 0.4], atol=1e-9)


def _empty() -> trimesh.Trimesh:
    return trimesh.Trimesh()


def test_fold_screw_helper_and_drop_empty_leaf():
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    parts = [TwinPart(0, "base", box), TwinPart(1, "helper", _empty()), TwinPart(2, "cap", box.copy()),
             TwinPart(3, "ghost", _empty())]
    z = np.array([0.0, 0.0, 1.0])
    o = np.array([0.1, 0.0, 0.0])
    joints = [Joint("slide", "prismatic", 0, 1, z, o, (0.0, 0.1)),
              Joint("spin", "revolute", 1, 2, -z, o + 0.3 * z, None, {"urdf_type": "continuous"}),
              Joint("dangling", "revolute", 0, 3, z, o, (0.0, 1.0))]
    twin, notes = fold_helper_parts(Twin("t", parts, joints))
    assert [p.name for p in twin.parts] == ["base", "cap"]
    (j,) = twin.joints
    assert (j.name, j.type, j.parent, j.child, j.limits) == ("slide", "prismatic", 0, 1, (0.0, 0.1))
    assert j.extra["folded"]["kind"] == "screw" and j.extra["folded"]["dropped"]["name"] == "spin"
    assert len(notes) == 2 and any("ghost" in n for n in notes)


def test_fold_non_collinear_chain_is_recorded_as_chain():
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    parts = [TwinPart(0, "base", box), TwinPart(1, "helper", _empty()), TwinPart(2, "arm", box.copy())]
    joints = [Joint("a", "revolute", 0, 1, np.array([0.0, 0, 1]), np.zeros(3), (0.0, 1.0)),
              Joint("b", "revolute", 1, 2, np.array([1.0, 0, 0]), np.zeros(3), (0.0, 1.0))]
    twin, _ = fold_helper_parts(Twin("t", parts, joints))
    assert twin.joints[0].name == "a" and twin.joints[0].extra["folded"]["kind"] == "chain"


def test_watertight_copy_of_an_open_sheet_is_closed_and_close():
    sheet = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    pitch = 1 / 64
    wt, info = watertight_copy(sheet, pitch)
    assert info["method"] == "udf-offset" and wt.is_watertight and wt.volume > 0
    level = 0.75 * pitch
    # a slab of thickness 2·level around the sheet: its volume and its distance to the sheet
    assert wt.volume == pytest.approx(2 * level, rel=0.1)
    d = np.abs(trimesh.sample.sample_surface(wt, 2000, seed=0)[0][:, 2])
    assert np.all(d < 1.5 * level)
    assert info["chamfer_vs_original"] < info["chamfer_floor"] + 2000 * level ** 2 * 1.5


def test_convert_usd_cli_roundtrip_and_bad_file(urdf_dir, tmp_path, capsys):
    """`rsart convert usd` is wired to rsart.sources.usd_twin.convert_usd: the USD rsart writes comes back."""
    (urdf_dir / "robot.urdf").write_text(_good())
    first = tmp_path / "a"
    assert main(["convert", "urdf", str(urdf_dir / "robot.urdf"), "--out", str(first), *FAST]) == 0
    back = tmp_path / "b"
    assert main(["convert", "usd", str(first / "twin" / "object.usda"), "--out", str(back), "--category", "box"]) == 0
    a, b = read_meta(first), read_meta(back)
    # provenance kept through the USD: the original source, with the file it came back from
    assert b.source["kind"] == "urdf" and b.source["converted_from"] == {"kind": "usd", "file": "object.usda"}
    assert b.object_id == a.object_id and b.category == "box"
    (ja,), (jb,) = a.joints, b.joints
    assert jb.type == ja.type and jb.limits == pytest.approx(ja.limits)
    np.testing.assert_allclose(jb.axis, ja.axis, atol=1e-6)
    np.testing.assert_allclose(np.cross(jb.origin - ja.origin, ja.axis), 0, atol=1e-6)  # same axis line
    bad = tmp_path / "bad.usda"
    bad.write_text("#usda 1.0\nthis is not usd (\n")
    capsys.readouterr()
    assert main(["convert", "usd", str(bad), "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "bad.usda" in err and "Traceback" not in err and not (tmp_path / "c").exists()


@pytest.mark.parametrize("opt,value", [("--scale", "0"), ("--scale", "-2"), ("--scale", "nan")])
def test_bad_scale_option(opt, value, urdf_dir, tmp_path, capsys):
    (urdf_dir / "robot.urdf").write_text(_good())
    assert main(["convert", "urdf", str(urdf_dir / "robot.urdf"), "--out", str(tmp_path / "o"), opt, value]) == 2
    err = capsys.readouterr().err
    assert "--scale must be a positive finite number" in err and not (tmp_path / "o").exists()
