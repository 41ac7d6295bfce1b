"""`rsart convert partnet-mobility` on the eight real PartNet-Mobility objects (RSART_PARTNET_ROOT).

The checks against mobility_v2.json are computed here independently of the importer: the JSON's
direction is turned into the URDF base frame with the root fixed joint's rpy, and the URDF joint must
equal it up to the documented rule (axis sign s = ±1; limits = s·JSON limits, plus whole turns for hinges).
"""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rsart
from rsart.cli import main
from rsart.format import read_meta
from rsart.sources.partnet import PARIS_ZUP_TO_WORLD, split_ids

IDS = ["100162", "100676", "101326", "101940", "148", "3763", "45213", "8867"]
RES = ["--resolution", "64", "-q"]


@pytest.fixture(scope="module")
def converted(partnet_root, tmp_path_factory) -> Path:
    """All eight objects converted once (coarse watertight grid to keep the suite fast)."""
    out = tmp_path_factory.mktemp("pm") / "ds"
    assert main(["convert", "partnet-mobility", "--root", str(partnet_root), "--ids", ",".join(IDS),
                 "--out", str(out), *RES]) == 0
    return out


def _xml(partnet_root: Path, i: str) -> ET.Element:
    return ET.parse(partnet_root / i / "mobility.urdf").getroot()  # trusted test asset


def _root_rotation(root: ET.Element) -> np.ndarray:
    """Rotation of the fixed joint from `base` to the root body (the annotation frame of mobility_v2.json)."""
    for j in root.findall("joint"):
        if j.find("parent").get("link") == "base":
            o = j.find("origin")
            rpy = [float(x) for x in (o.get("rpy") or "0 0 0").split()]
            return trimesh.transformations.euler_matrix(*rpy, axes="sxyz")[:3, :3]
    raise AssertionError("no joint from base")


def _child_link(root: ET.Element, joint_name: str) -> str:
    for j in root.findall("joint"):
        if j.get("name") == joint_name:
            return j.find("child").get("link")
    raise AssertionError(joint_name)


def test_all_eight_convert_load_and_pose(converted):
    ds = rsart.load(converted)
    assert sorted(ds) == sorted(f"pm-{i}" for i in IDS)
    for oid in ds:
        obj = ds[oid]
        meta = obj.meta
        assert meta.units == "scene" and meta.source["kind"] == "partnet-mobility"
        assert [s.id for s in meta.states][:4] == ["m0", "m1", "m2", "m3"]
        assert meta.eval_states == {"start": "m0", "end": "m3"}
        twin = obj.twin
        for p in meta.parts:
            m = trimesh.load(converted / oid / p.mesh, process=False)
            assert m.is_watertight and m.volume > 0, (oid, p.name)
            assert p.extra["watertight"]["watertight"] is True
        rest = twin.posed_meshes({})
        for s in meta.states:
            T = twin.pose(s.values)
            posed = twin.posed_meshes(s.values)
            for j in twin.joints:
                if j.parent == 0:  # a part hanging from the base moves exactly when its joint is not 0
                    assert np.allclose(T[j.child], np.eye(4)) == (abs(s.values[j.name]) < 1e-12), (oid, s.id)
            for m in posed:
                assert np.all(np.isfinite(m.vertices))
        # the multi states move every part by its range: the end state differs from the start state
        Ts, Te = twin.pose(meta.state("m0").values), twin.pose(meta.state("m3").values)
        for j in twin.joints:
            assert not np.allclose(Ts[j.child], Te[j.child]), (oid, j.name)
        assert len(rest) == len(meta.parts)


def test_axes_and_limits_match_mobility_v2(converted, partnet_root):
    n_checked = 0
    for i in IDS:
        meta = read_meta(converted / f"pm-{i}")
        root = _xml(partnet_root, i)
        R = _root_rotation(root)
        mob = {e["id"]: e for e in json.loads((partnet_root / i / "mobility_v2.json").read_text())}
        for j in meta.joints:
            link = _child_link(root, j.extra["urdf_joint"])
            e = mob[int(link.split("_")[1])]
            jd = e["jointData"]
            d = R @ np.asarray(jd["axis"]["direction"], float)
            d /= np.linalg.norm(d)
            assert abs(abs(np.dot(d, j.axis)) - 1) < 1e-6, (i, j.name)
            s = 1.0 if np.dot(d, j.axis) > 0 else -1.0
            a, b = jd["limit"]["a"], jd["limit"]["b"]
            if j.limits is None:
                assert jd["limit"]["noLimit"] is True, (i, j.name)
                continue
            lo, hi = j.limits
            assert lo < hi
            if j.type == "revolute":
                k = round((lo - s * math.radians(a)) / (2 * math.pi))
                assert lo == pytest.approx(s * math.radians(a) + 2 * math.pi * k, abs=1e-6), (i, j.name)
                assert hi == pytest.approx(s * math.radians(b) + 2 * math.pi * k, abs=1e-6), (i, j.name)
            else:
                assert (lo, hi) == pytest.approx((s * a, s * b), abs=1e-9), (i, j.name)
            # the importer records the same sign
            assert j.extra["mobility_v2"]["sign"] == s and j.extra["mobility_v2"]["agrees"] is True
            n_checked += 1
    assert n_checked == 18  # every limited joint of the eight objects (the 4 knobs are unlimited)


def test_limit_without_effort_and_velocity_is_accepted(converted, partnet_root):
    for i in IDS:
        lims = _xml(partnet_root, i).iter("limit")
        assert all(l.get("effort") is None and l.get("velocity") is None for l in lims)
        assert (converted / f"pm-{i}" / "meta.json").is_file()


def test_non_unit_axes_limits_beyond_a_turn_and_reversed_limits(converted, partnet_root):
    root = _xml(partnet_root, "100676")
    norms = [np.linalg.norm([float(x) for x in a.get("xyz").split()]) for a in root.iter("axis")]
    assert min(abs(n - 1) for n in norms) > 0.01  # every raw axis is non-unit
    mob = json.loads((partnet_root / "100676" / "mobility_v2.json").read_text())
    lims = [e["jointData"]["limit"] for e in mob if e["jointData"]]
    assert min(l["a"] for l in lims) < -360 and sum(l["a"] > l["b"] for l in lims) == 2
    meta = read_meta(converted / "pm-100676")
    for j in meta.joints:
        assert np.linalg.norm(j.axis) == pytest.approx(1.0, abs=1e-9)
        assert -2 * math.pi < j.limits[0] < j.limits[1] < 2 * math.pi
    signs = [j.extra["mobility_v2"]["sign"] for j in meta.joints]
    turns = [j.extra["mobility_v2"]["turns"] for j in meta.joints]
    assert signs == [1, 1, -1, -1] and turns == [1, 0, 0, 0]


def test_continuous_knobs_get_a_quarter_turn(converted):
    meta = read_meta(converted / "pm-101940")
    knobs = [j for j in meta.joints if j.extra.get("urdf_type") == "continuous"]
    assert len(knobs) == 4 and all(j.limits is None and j.type == "revolute" for j in knobs)
    note = meta.extra["unlimited_joints"]
    assert sorted(note["joints"]) == sorted(j.name for j in knobs)
    assert note["state_range"] == pytest.approx([0.0, math.pi / 2])
    for s in meta.states:
        for j in knobs:
            assert 0.0 <= s.values[j.name] <= math.pi / 2 + 1e-12
    assert meta.state("m3").values[knobs[0].name] == pytest.approx(math.pi / 2)


def test_screw_cap_is_one_prismatic_joint_with_the_spin_recorded(converted):
    meta = read_meta(converted / "pm-3763")
    assert [p.name for p in meta.parts] == ["base", "rotation_lid_0"]
    (j,) = meta.joints
    assert j.type == "prismatic" and j.limits == pytest.approx((-0.108, -0.008))
    f = j.extra["folded"]
    assert f["kind"] == "screw" and f["helper_links"] == ["link_0_helper"]
    assert f["dropped"]["type"] == "revolute" and f["dropped"]["urdf_type"] == "continuous"
    assert abs(abs(np.dot(f["dropped"]["axis"], j.axis)) - 1) < 1e-9
    assert any("link_0_helper" in n for n in meta.extra["conversion_notes"])
    twin = rsart.load(converted / "pm-3763").twin
    lo, hi = twin.pose({j.name: j.limits[0]}), twin.pose({j.name: j.limits[1]})
    np.testing.assert_allclose(hi[1][:3, 3] - lo[1][:3, 3], 0.1 * j.axis, atol=1e-9)


def test_repeated_visual_names_keep_every_mesh(converted, partnet_root):
    root = _xml(partnet_root, "101940")
    names = [v.get("name") for v in root.iter("visual")]
    assert len(names) > len(set(names))  # the quirk is present
    meta = read_meta(converted / "pm-101940")
    for p in meta.parts:
        files = [v.find("geometry/mesh").get("filename") for l in root.findall("link")
                 if l.get("name") in p.extra["links"] for v in l.findall("visual")]
        want = sum(len(trimesh.load(partnet_root / "101940" / f, force="mesh", process=False).faces) for f in files)
        got = trimesh.load(converted / "pm-101940" / p.extra["visual"], force="mesh", process=False)
        assert len(got.faces) == want, p.name


def test_links_without_geometry_are_merged_or_folded(converted):
    for i in IDS:
        meta = read_meta(converted / f"pm-{i}")
        assert meta.parts[0].name == "base" and "base" in meta.parts[0].extra["links"]
        assert len(meta.parts[0].extra["links"]) == 2  # the empty `base` link + the root body


def test_source_ids_category_names_and_frame(converted):
    meta = read_meta(converted / "pm-100676")
    assert meta.source == {"kind": "partnet-mobility", "id": "100676", "anno_id": "676",
                           "model_id": "f844d0a2f4e28c5e4f9794688920aecc", "version": "1"}
    assert meta.category == "Box" and meta.object_id == "pm-100676"
    assert [p.name for p in meta.parts] == ["base", "rotation_lid_0", "rotation_lid_1", "rotation_lid_2",
                                            "rotation_lid_3"]
    assert meta.parts[0].extra["semantic"] == "box_body"
    assert read_meta(converted / "pm-45213").category == "StorageFurniture"
    # z up: the door stands along z
    door = rsart.load(converted / "pm-8867").twin
    ext = door.bounds()[1] - door.bounds()[0]
    assert np.argmax(ext) == 2


def test_metric_scale(partnet_root, converted, tmp_path, capsys):
    out = tmp_path / "m"
    assert main(["convert", "partnet-mobility", str(partnet_root / "45213"), "--out", str(out),
                 "--metric-scale", "0.5", *RES]) == 0
    m, s = read_meta(out), read_meta(converted / "pm-45213")
    assert m.units == "m" and m.extra["scale_to_metres"] == 0.5
    for jm, js in zip(m.joints, s.joints):
        np.testing.assert_allclose(jm.origin, 0.5 * js.origin, atol=1e-12)
        np.testing.assert_allclose(jm.axis, js.axis)
        if jm.type == "prismatic":
            assert jm.limits == pytest.approx((0.5 * js.limits[0], 0.5 * js.limits[1]))
        else:
            assert jm.limits == js.limits
    a = rsart.load(out).twin.bounds()
    b = rsart.load(converted / "pm-45213").twin.bounds()
    np.testing.assert_allclose(a, 0.5 * b, atol=0.01)  # watertight offsets differ slightly


def test_pd2gs_paper_split(partnet_root, tmp_path, capsys):
    ids = split_ids("pd2gs-paper")
    assert ids == ["100676", "102373", "9168", "7187", "12248", "47254", "45194", "45271", "45612", "23372",
                   "30666", "33810"]
    out = tmp_path / "ds"
    assert main(["convert", "partnet-mobility", "--root", str(partnet_root), "--split", "pd2gs-paper",
                 "--out", str(out), "--resolution", "32", "-q"]) == 0
    cap = capsys.readouterr()
    assert "converted 1/12" in cap.out and "missing" in cap.err and "102373" in cap.err
    # -q: one summary line per object and the batch line, nothing else (no progress bar, no raw dicts)
    assert cap.out.count("\n") == 2 and "pm-100676 [Box]" in cap.out and "{" not in cap.err
    idx = json.loads((out / "index.json").read_text())
    assert idx["splits"] == {"pd2gs-paper": ["pm-100676"]}
    # a re-run keeps the finished object (an interrupted batch resumes) and still succeeds
    before = (out / "pm-100676" / "meta.json").stat().st_mtime_ns
    assert main(["convert", "partnet-mobility", "--root", str(partnet_root), "--split", "pd2gs-paper",
                 "--out", str(out), "--resolution", "32", "-q"]) == 0
    out_text = capsys.readouterr().out
    assert "pm-100676: exists, kept" in out_text and "converted 0/12, kept 1" in out_text
    assert (out / "pm-100676" / "meta.json").stat().st_mtime_ns == before


def test_world_frame_relates_to_the_paris_z_up_frame(partnet_root):
    """PARIS/DTArt turn the y-up annotation frame by R_coord (+90° about x); the URDF root joint adds -90° about z."""
    r_coord = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    for i in IDS:
        R = _root_rotation(_xml(partnet_root, i))
        np.testing.assert_allclose(R, PARIS_ZUP_TO_WORLD @ r_coord, atol=1e-12)


def test_ray_cast_masks_cover_the_right_parts(converted):
    """Depth/masks from the watertight copies (the capture simulator's ray caster) agree with the original
    textured meshes: a pixel labelled part i lies on part i's own original surface, in every multi state."""
    import math as _m

    from scipy.spatial import cKDTree

    from rsart.camera import Camera, Intrinsics
    from rsart.render.paths import bounding_sphere, fit_radius, orbit_pose
    from rsart.render.raycast import build_scene

    obj = rsart.load(converted / "pm-45213")
    twin = obj.twin
    K = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5, None)
    for sid in ("m0", "m3"):
        values = obj.meta.state(sid).values
        scene = build_scene([[m] for m in twin.posed_meshes(values)])
        vis = [trimesh.util.concatenate(ms) for ms in twin.posed_visuals(values)]
        trees = [cKDTree(trimesh.sample.sample_surface(v, 40000, seed=0)[0]) for v in vis]
        centre, _ = bounding_sphere(twin.bounds(values))
        seen = set()
        for az in (-0.8, 0.0, 0.8):  # the drawers/door face -x in this object
            cam = Camera(K, orbit_pose(centre, fit_radius(twin.bounds(values), K), _m.pi + az, 0.5))
            hits = scene.cast(cam)
            pts = scene.hit_points(hits, cam)
            for i in np.unique(hits.label[hits.hit]):
                p = pts[hits.label == i]
                d = np.stack([t.query(p)[0] for t in trees], axis=1)
                # nearest original surface is the labelled part's for (almost) every pixel
                assert np.mean(np.argmin(d, axis=1) == i) > 0.97, (sid, i)
                seen.add(int(i))
        if sid == "m3":  # everything open: every part is in view (closed, the door hides the drawers)
            assert seen == set(range(len(twin.parts))), (sid, seen)


# 100162's lids are single flat quads; twin/object.urdf uses the visual OBJ as collision geometry too, and
# MuJoCo cannot build a convex hull of coplanar vertices (a rsart.urdf writer matter, reported to the lead).
MUJOCO_KNOWN = {"100162": "flat visual mesh used as collision geometry: MuJoCo cannot hull coplanar vertices"}


@pytest.mark.parametrize("i", [pytest.param(i, marks=pytest.mark.xfail(reason=MUJOCO_KNOWN[i], strict=False))
                               if i in MUJOCO_KNOWN else i for i in IDS])
def test_written_urdf_poses_like_the_twin_in_mujoco(i, converted):
    """The object.urdf written for a converted object loads in MuJoCo and poses every part as rsart does."""
    from rsart.mujoco_check import mujoco_pose_error

    obj = rsart.load(converted / f"pm-{i}")
    urdf = converted / f"pm-{i}" / "twin" / "object.urdf"
    err = max(mujoco_pose_error(obj.twin, urdf, s.values) for s in obj.meta.states)
    assert err < 1e-9, (i, err)
