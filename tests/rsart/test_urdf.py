"""URDF reading (real PartNet-Mobility files, hostile files) and the URDF -> twin -> URDF round trip."""
import math

import numpy as np
import pytest

from rsart.errors import RsartError
from rsart.mujoco_check import mujoco_pose_error
from rsart.twin_io import read_twin, write_object
from rsart.urdf import read_urdf
from tests.conftest import PARTNET_IDS, make_cabinet, make_lamp


def random_values(twin, rng):
    return {j.name: float(rng.uniform(*j.limits)) if j.limits else float(rng.uniform(-3, 3)) for j in twin.joints}


@pytest.mark.parametrize("pid", PARTNET_IDS)
def test_partnet_mobility_urdf_loads_as_twin(partnet_root, pid):
    t = read_urdf(partnet_root / pid / "mobility.urdf")
    assert len(t.parts) >= 2 and len(t.joints) == len(t.parts) - 1
    for j in t.joints:
        assert abs(np.linalg.norm(j.axis) - 1) < 1e-9
        assert j.type in ("revolute", "prismatic")
    # every part that has geometry got it; the base has geometry
    assert len(t.parts[0].mesh.faces) > 0
    t.pose(random_values(t, np.random.default_rng(0)))


def test_partnet_quirks(partnet_root):
    oven = read_urdf(partnet_root / "101940" / "mobility.urdf")
    knobs = [j for j in oven.joints if j.limits is None]
    assert len(knobs) == 4 and all(j.extra.get("urdf_type") == "continuous" for j in knobs)
    bottle = read_urdf(partnet_root / "3763" / "mobility.urdf")  # helper link declared after its joint
    types = sorted(j.type for j in bottle.joints)
    assert types == ["prismatic", "revolute"]
    helper = [p for p in bottle.parts if len(p.mesh.faces) == 0]
    assert [p.name for p in helper] == ["link_0_helper"]


@pytest.mark.parametrize("make", [make_cabinet, make_lamp])
def test_urdf_round_trip_and_mujoco_agree(tmp_path, make):
    twin = make()
    write_object(twin, tmp_path / "o", object_id="o", category="t", source={"kind": "procedural", "id": "t"})
    back = read_urdf(tmp_path / "o" / "twin" / "object.urdf")
    stored = read_twin(tmp_path / "o")
    rng = np.random.default_rng(1)
    for _ in range(5):
        vals = random_values(twin, rng)
        a = np.concatenate([m.vertices for m in twin.posed_meshes(vals)])
        for other in (back, stored):
            b = np.concatenate([m.vertices for m in other.posed_meshes(vals)])
            assert np.abs(a - b).max() < 1e-6
        assert mujoco_pose_error(stored, tmp_path / "o" / "twin" / "object.urdf", vals) < 1e-9


URDF_OK_LINK = '<link name="base"><visual><geometry><box size="1 1 1"/></geometry></visual></link>'


def write(tmp_path, body, name="bad.urdf"):
    p = tmp_path / name
    p.write_text(body)
    return p


BAD_URDFS = {
    "billion_laughs": ('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;">]>'
                       '<robot name="&lol2;">' + URDF_OK_LINK + '</robot>', "DTD or entities"),
    "external_entity": ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
                        '<robot name="&x;">' + URDF_OK_LINK + '</robot>', "DTD or entities"),
    "not_xml": ("<robot name='x'><link", "not well-formed"),
    "unknown_joint_type": ('<robot name="r">' + URDF_OK_LINK + '<link name="a"/><joint name="j" type="floating">'
                           '<parent link="base"/><child link="a"/></joint></robot>', "unsupported joint type"),
    "zero_axis": ('<robot name="r">' + URDF_OK_LINK + '<link name="a"/><joint name="j" type="revolute"><axis xyz="0 0 0"/>'
                  '<limit lower="0" upper="1"/><parent link="base"/><child link="a"/></joint></robot>', "zero-length"),
    "nan_origin": ('<robot name="r">' + URDF_OK_LINK + '<link name="a"/><joint name="j" type="revolute"><origin xyz="nan 0 0"/>'
                   '<limit lower="0" upper="1"/><parent link="base"/><child link="a"/></joint></robot>', "non-finite"),
    "two_roots": ('<robot name="r">' + URDF_OK_LINK + '<link name="a"/></robot>', "exactly one root"),
    "cycle": ('<robot name="r"><link name="a"/><link name="b"/><joint name="j1" type="fixed"><parent link="a"/>'
              '<child link="b"/></joint><joint name="j2" type="fixed"><parent link="b"/><child link="a"/></joint></robot>',
              "root"),
    "unknown_link": ('<robot name="r">' + URDF_OK_LINK + '<joint name="j" type="fixed"><parent link="base"/>'
                     '<child link="ghost"/></joint></robot>', "unknown link"),
    "missing_mesh": ('<robot name="r"><link name="base"><visual><geometry><mesh filename="nope.obj"/></geometry>'
                     '</visual></link></robot>', "not found"),
    "mesh_escapes": ('<robot name="r"><link name="base"><visual><geometry><mesh filename="../../etc/passwd"/>'
                     '</geometry></visual></link></robot>', "leaves the URDF folder"),
    "absolute_mesh": ('<robot name="r"><link name="base"><visual><geometry><mesh filename="/etc/passwd"/>'
                      '</geometry></visual></link></robot>', "absolute mesh path"),
    "prismatic_without_limit": ('<robot name="r">' + URDF_OK_LINK + '<link name="a"/><joint name="j" type="prismatic">'
                                '<parent link="base"/><child link="a"/></joint></robot>', "needs <limit"),
    "lower_gt_upper": ('<robot name="r">' + URDF_OK_LINK + '<link name="a"/><joint name="j" type="revolute">'
                       '<limit lower="2" upper="1"/><parent link="base"/><child link="a"/></joint></robot>', "lower 2.0 > upper"),
}


@pytest.mark.parametrize("case", sorted(BAD_URDFS))
def test_hostile_or_broken_urdf_gives_specific_error(tmp_path, case):
    body, msg = BAD_URDFS[case]
    sub = tmp_path / "a" / "b"
    sub.mkdir(parents=True)
    p = write(sub, body)
    with pytest.raises(RsartError) as e:
        read_urdf(p)
    assert msg in str(e.value) and "bad.urdf" in str(e.value)


def test_limit_without_effort_and_velocity_is_accepted(tmp_path):
    p = write(tmp_path, '<robot name="r">' + URDF_OK_LINK + '<link name="a"><visual><geometry><box size="1 1 1"/>'
              '</geometry></visual></link><joint name="j" type="revolute"><axis xyz="0 0 2"/>'
              '<limit lower="-1" upper="1"/><parent link="base"/><child link="a"/></joint></robot>', "ok.urdf")
    t = read_urdf(p)
    np.testing.assert_allclose(t.joints[0].axis, [0, 0, 1])  # non-unit axis normalised
    assert t.joints[0].limits == (-1.0, 1.0)
