"""meta.json / cameras.json / index.json validation: every problem named with its JSON path."""
import copy
import json

import numpy as np
import pytest

from rsart.errors import ValidationError
from rsart.format import (CamerasFile, ViewRecord, parse_cameras, parse_index, parse_meta, read_meta,
                          meta_to_dict, write_cameras, read_cameras)
from rsart.camera import Intrinsics

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)

META = {
    "format": "rsart/1", "object_id": "storage-0003", "category": "storage",
    "source": {"kind": "procedural", "id": "storage:3"}, "units": "m",
    "twin": {"urdf": "twin/object.urdf", "usd": "twin/object.usda"},
    "parts": [{"index": 0, "name": "base", "mesh": "twin/parts/base.ply"},
              {"index": 1, "name": "drawer_0", "mesh": "twin/parts/drawer_0.ply"}],
    "joints": [{"name": "drawer_0_slide", "type": "prismatic", "parent": 0, "child": 1,
                "axis": [1, 0, 0], "origin": [0.0, 0.0, 0.2], "limits": [0.0, 0.3]}],
    "states": [{"id": "m0", "kind": "multi", "values": {"drawer_0_slide": 0.0}},
               {"id": "s1max", "kind": "single", "joint": "drawer_0_slide", "extreme": "max",
                "values": {"drawer_0_slide": 0.3}}],
    "eval_states": {"start": "m0", "end": "s1max"},
}
CAMS = {"intrinsics": {"width": 640, "height": 480, "fx": 600.0, "fy": 600.0, "cx": 319.5, "cy": 239.5,
                       "distortion": None},
        "depth_scale": 0.001,
        "views": [{"id": "0000", "c2w": np.eye(4).tolist(), "split": "train"}]}


def test_design_example_is_valid_and_round_trips():
    m = parse_meta(META)
    assert m.joints[0].limits == (0.0, 0.3)
    assert m.state("s1max").extreme == "max"
    d = meta_to_dict(m)
    assert meta_to_dict(parse_meta(json.loads(json.dumps(d)))) == d
    assert d["joints"][0]["axis"] == [1.0, 0.0, 0.0] and d["states"][1]["joint"] == "drawer_0_slide"


def mutate(path_fn):
    d = copy.deepcopy(META)
    path_fn(d)
    return d


def _set(keys, value):
    def f(d):
        x = d
        for k in keys[:-1]:
            x = x[k]
        x[keys[-1]] = value
    return f


def _del(keys):
    def f(d):
        x = d
        for k in keys[:-1]:
            x = x[k]
        del x[keys[-1]]
    return f


META_CASES = [
    (_set(["joints", 0, "axis"], [0, 0, 0]), "joints[0].axis", "zero-length"),
    (_set(["joints", 0, "axis"], [1, 1, 0]), "joints[0].axis", "not a unit vector"),
    (_set(["joints", 0, "axis"], [1, 0]), "joints[0].axis", "list of 3"),
    (_set(["joints", 0, "origin"], [0, float("nan"), 0]), "joints[0].origin", "non-finite"),
    (_set(["joints", 0, "type"], "screw"), "joints[0].type", "not one of"),
    (_set(["joints", 0, "child"], 0), "joints[0].child", "static base"),
    (_set(["joints", 0, "child"], 7), "joints[0].child", "part index"),
    (_set(["joints", 0, "limits"], [0.3, 0.0]), "joints[0].limits", "lower 0.3 > upper"),
    (_set(["joints", 0, "limits"], None), "joints[0].limits", "needs limits"),
    (_del(["joints", 0, "name"]), "joints[0].name", "missing"),
    (_set(["parts", 1, "index"], 5), "parts[1].index", "position 1"),
    (_set(["parts", 1, "name"], "base"), "parts[1].name", "duplicate"),
    (_set(["parts", 1, "mesh"], "../../etc/passwd"), "parts[1].mesh", "relative path inside"),
    (_set(["parts", 1, "mesh"], "/abs/mesh.ply"), "parts[1].mesh", "relative path inside"),
    (_set(["states", 0, "values"], {"drawer_0_slide": 0.9}), "states[0].values.drawer_0_slide", "outside the joint limits"),
    (_set(["states", 0, "values"], {}), "states[0].values.drawer_0_slide", "missing"),
    (_set(["states", 0, "values"], {"drawer_0_slide": 0.0, "ghost": 1.0}), "states[0].values.ghost", "unknown joint"),
    (_set(["states", 1, "extreme"], "middle"), "states[1].extreme", "'min' or 'max'"),
    (_set(["states", 1, "id"], "m0"), "states[1].id", "duplicate"),
    (_set(["states", 0, "kind"], "both"), "states[0].kind", "not one of"),
    (_set(["eval_states", "end"], "m9"), "eval_states.end", "unknown state"),
    (_set(["units"], "inch"), "units", "not one of"),
    (_set(["format"], "rsart/9"), "format", "unsupported"),
    (_set(["object_id"], "a/b"), "object_id", "safe id"),
    (_del(["parts"]), "parts", "missing"),
    (_set(["joints"], []), "joints", "part 1 is not the child"),
]


@pytest.mark.parametrize("fn,path,msg", META_CASES, ids=[f"{c[1]}-{c[2]}" for c in META_CASES])
def test_malformed_meta_names_its_path(fn, path, msg):
    with pytest.raises(ValidationError) as e:
        parse_meta(mutate(fn), source="meta.json")
    text = str(e.value)
    assert any(p.path == path and msg in p.message for p in e.value.problems), text
    assert "meta.json" in text


def test_every_problem_is_listed_not_just_the_first():
    d = copy.deepcopy(META)
    d["joints"][0]["axis"] = [0, 0, 0]
    d["units"] = "inch"
    d["states"][0]["kind"] = "x"
    with pytest.raises(ValidationError) as e:
        parse_meta(d)
    paths = {p.path for p in e.value.problems}
    assert {"joints[0].axis", "units", "states[0].kind"} <= paths


def test_joint_cycle_is_reported():
    d = copy.deepcopy(META)
    d["parts"].append({"index": 2, "name": "p2", "mesh": "twin/parts/p2.ply"})
    d["joints"][0]["parent"] = 2
    d["joints"].append({"name": "j2", "type": "revolute", "parent": 1, "child": 2, "axis": [0, 0, 1],
                        "origin": [0, 0, 0], "limits": None})
    for s in d["states"]:
        s["values"]["j2"] = 0.0
    with pytest.raises(ValidationError, match="cycle"):
        parse_meta(d)


def test_read_meta_reports_bad_json_with_file(tmp_path):
    p = tmp_path / "meta.json"
    p.write_text('{"format": "rsart/1", ')
    with pytest.raises(Exception, match="meta.json: invalid JSON"):
        read_meta(p)
    p.write_text('{"x": NaN}')
    with pytest.raises(Exception, match="non-finite"):
        read_meta(p)


CAM_CASES = [
    (_set(["intrinsics", "fx"], -1.0), "intrinsics.fx", "positive"),
    (_set(["intrinsics", "width"], 640.5), "intrinsics.width", "positive integer"),
    (_set(["intrinsics", "distortion"], "none"), "intrinsics.distortion", "list of finite"),
    (_set(["depth_scale"], 0), "depth_scale", "positive"),
    (_set(["views", 0, "c2w"], [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]), "views[0].c2w", "4x4"),
    (_set(["views", 0, "c2w"], [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "views[0].c2w", "proper rotation"),
    (_set(["views", 0, "c2w"], [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]), "views[0].c2w", "last row"),
    (_set(["views", 0, "split"], "val"), "views[0].split", "not one of"),
    (_del(["views", 0, "id"]), "views[0].id", "missing"),
    (_del(["intrinsics", "cy"]), "intrinsics.cy", "missing"),
]


@pytest.mark.parametrize("fn,path,msg", CAM_CASES, ids=[f"{c[1]}-{c[2]}" for c in CAM_CASES])
def test_malformed_cameras_names_its_path(fn, path, msg):
    d = copy.deepcopy(CAMS)
    fn(d)
    with pytest.raises(ValidationError) as e:
        parse_cameras(d, source="cameras.json")
    assert any(p.path == path and msg in p.message for p in e.value.problems), str(e.value)


def test_cameras_round_trip(tmp_path):
    c = CamerasFile(Intrinsics(64, 48, 50.0, 51.0, 31.5, 23.5), 0.001,
                    [ViewRecord("0000", np.eye(4), "train"), ViewRecord("0001", np.eye(4), "test", {"t": 1.5})])
    write_cameras(c, tmp_path / "cameras.json")
    c2 = read_cameras(tmp_path / "cameras.json")
    assert c2.intrinsics == c.intrinsics and c2.views[1].extra == {"t": 1.5} and c2.views[1].split == "test"


def test_index_validation():
    good = {"format": "rsart/1", "name": "x", "version": "1", "objects": ["a", "b"], "splits": {"all": ["a", "b"]}}
    assert parse_index(good).objects == ["a", "b"]
    bad = dict(good, splits={"all": ["a", "zz"]})
    with pytest.raises(ValidationError, match=r"splits.all\[1\]"):
        parse_index(bad)


def test_writers_refuse_what_readers_would_reject(tmp_path):
    """write_cameras / write_index validate what they write, as write_meta does: nothing is left on disk."""
    from rsart.format import DatasetIndex, write_index

    flipped = np.diag([1.0, 1.0, -1.0, 1.0])  # a reflection, not a rotation
    c = CamerasFile(Intrinsics(64, 48, 50.0, 51.0, 31.5, 23.5), 0.001,
                    [ViewRecord("0000", np.eye(4), "train"), ViewRecord("../up", flipped, "train")])
    with pytest.raises(ValidationError) as e:
        write_cameras(c, tmp_path / "cameras.json")
    assert "views[1].id" in str(e.value) and "views[1].c2w" in str(e.value)
    assert not (tmp_path / "cameras.json").exists()

    idx = DatasetIndex("x", "1", ["a"], {"all": ["a", "b"]})
    with pytest.raises(ValidationError, match=r"splits.all\[1\]"):
        write_index(idx, tmp_path)
    assert not (tmp_path / "index.json").exists()
