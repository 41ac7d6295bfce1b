"""Twin -> rsart USD (.usda) -> Twin: same parts, joints, limits, textures and posed meshes (within 1e-6 m)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from PIL import Image

from rsart.format import Joint
from rsart.kinematics import Twin, TwinPart
from rsart.usd import read_usd, write_usd

pxr = pytest.importorskip("pxr")
from pxr import Sdf, Usd, UsdGeom, UsdPhysics  # noqa: E402


def _box(extents, center) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(center)
    return m


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def make_mixed() -> Twin:
    """Base + a door on an off-origin, tilted hinge + an arm chained on the door (second hinge) + a drawer
    sliding along a non-axis-aligned direction + an unlimited knob. Names need prim-name sanitising."""
    base = _box([0.6, 0.5, 0.4], [0.1, -0.2, 0.2])
    door = _box([0.03, 0.45, 0.35], [0.42, -0.2, 0.22])
    arm = trimesh.creation.icosphere(subdivisions=2, radius=0.04)
    arm.apply_translation([0.47, 0.0, 0.3])
    drawer = _box([0.3, 0.3, 0.08], [0.05, -0.25, 0.05])
    knob = trimesh.creation.cylinder(radius=0.02, height=0.03, sections=16)
    knob.apply_translation([0.1, -0.2, 0.415])
    parts = [TwinPart(0, "base", base, extra={"label": "body", "links": ["a", "b"]}),
             TwinPart(1, "door-1", door), TwinPart(2, "0arm.x", arm),
             TwinPart(3, "drawer", drawer), TwinPart(4, "knob", knob)]
    joints = [
        Joint("door-hinge", "revolute", 0, 1, _unit([0.1, 0.2, 1.0]), np.array([0.4, 0.03, 0.05]), (-0.3, 1.9)),
        Joint("arm.elbow", "revolute", 1, 2, _unit([1.0, -0.4, 0.3]), np.array([0.45, -0.05, 0.3]), (-2.5, 0.7)),
        Joint("drawer_slide", "prismatic", 0, 3, _unit([1.0, 0.3, -0.1]), np.array([0.2, -0.2, 0.05]), (0.0, 0.27),
              extra={"damping": 0.5}),
        Joint("knob_spin", "revolute", 0, 4, np.array([0.0, 0.0, -1.0]), np.array([0.1, -0.2, 0.4]), None),
    ]
    return Twin("mixed object", parts, joints)


def _random_values(twin: Twin, rng: np.random.Generator) -> dict[str, float]:
    out = {}
    for j in twin.joints:
        lo, hi = j.limits if j.limits is not None else (-2 * math.pi, 2 * math.pi)
        out[j.name] = float(rng.uniform(lo, hi))
    return out


def assert_same_posed(a: Twin, b: Twin, n: int = 12, tol: float = 1e-6, seed: int = 0) -> float:
    """Max vertex distance between the posed part meshes of ``a`` and ``b`` over ``n`` random configurations."""
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(n):
        q = _random_values(a, rng)
        for ma, mb in zip(a.posed_meshes(q), b.posed_meshes(q)):
            assert ma.vertices.shape == mb.vertices.shape
            assert np.array_equal(ma.faces, mb.faces)
            worst = max(worst, float(np.abs(ma.vertices - mb.vertices).max()))
    assert worst < tol, worst
    return worst


def _assert_same_structure(a: Twin, b: Twin, tol: float = 1e-9) -> None:
    assert [p.name for p in b.parts] == [p.name for p in a.parts]
    assert [p.extra for p in b.parts] == [p.extra for p in a.parts]
    assert [j.name for j in b.joints] == [j.name for j in a.joints]
    assert [j.extra for j in b.joints] == [j.extra for j in a.joints]
    for ja, jb in zip(a.joints, b.joints):
        assert (jb.type, jb.parent, jb.child) == (ja.type, ja.parent, ja.child)
        np.testing.assert_allclose(jb.axis, ja.axis, atol=tol)
        d = jb.origin - ja.origin  # same line: origin offset along the axis only
        assert np.linalg.norm(d - np.dot(d, ja.axis) * ja.axis) < tol
        if ja.limits is None:
            assert jb.limits is None
        else:
            np.testing.assert_allclose(jb.limits, ja.limits, atol=tol)


def test_roundtrip_mixed_object(tmp_path):
    twin = make_mixed()
    write_usd(twin, tmp_path / "object.usda")
    back = read_usd(tmp_path / "object.usda")
    _assert_same_structure(twin, back, tol=1e-12)
    assert back.name == twin.name
    worst = assert_same_posed(twin, back, n=20)
    assert worst < 1e-7  # float32 points stored relative to each part's centre


def test_roundtrip_with_usdphysics_attributes_only(tmp_path):
    """Dropping rsart's double-precision rsart:* copies, the UsdPhysics floats alone still give 1e-6 m."""
    twin = make_mixed()
    write_usd(twin, tmp_path / "object.usda")
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "object.usda"))
    stage = Usd.Stage.Open(layer)
    removed = 0
    for prim in stage.Traverse():
        for a in prim.GetAttributes():
            if a.GetName() in ("rsart:axis", "rsart:origin", "rsart:limits"):
                prim.RemoveProperty(a.GetName())
                removed += 1
    assert removed == 4 * 2 + 3  # axis + origin per joint, limits for the three limited joints
    layer.Export(str(tmp_path / "plain.usda"))
    back = read_usd(tmp_path / "plain.usda")
    _assert_same_structure(twin, back, tol=1e-6)
    assert_same_posed(twin, back, n=20, tol=1e-6)


def test_written_stage_is_a_usdphysics_articulation(tmp_path):
    twin = make_mixed()
    write_usd(twin, tmp_path / "object.usda")
    stage = Usd.Stage.Open(str(tmp_path / "object.usda"))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert stage.GetRootLayer().customLayerData["rsart:units"] == "m"
    # the reference UsdPhysics parser (independent of rsart's reader) sees one articulation with every body/joint
    parsed = UsdPhysics.UsdPhysicsLoadStageFromPrimRange(stage, ["/"])
    kinds = {str(k): v for k, v in parsed.items()}
    bodies = [str(p) for p in kinds["RigidBody"][0]]
    assert [b.rsplit("/", 1)[1] for b in bodies] == ["base", "door_1", "_0arm_x", "drawer", "knob"]
    assert len(kinds["Articulation"][0]) == 1
    rev = {str(p).rsplit("/", 1)[1]: d for p, d in zip(*kinds["RevoluteJoint"])}
    assert set(rev) == {"door_hinge", "arm_elbow", "knob_spin"}
    door = rev["door_hinge"]
    assert str(door.body0).endswith("/base") and str(door.body1).endswith("/door_1")
    assert door.limit.enabled
    assert door.limit.lower == pytest.approx(math.degrees(-0.3), abs=1e-4)
    assert door.limit.upper == pytest.approx(math.degrees(1.9), abs=1e-4)
    assert not rev["knob_spin"].limit.enabled
    pris = {str(p).rsplit("/", 1)[1]: d for p, d in zip(*kinds["PrismaticJoint"])}
    assert pris["drawer_slide"].limit.upper == pytest.approx(0.27, abs=1e-6)
    assert len(kinds["FixedJoint"][0]) == 1  # the base anchored to the world


def test_scene_units_recorded(tmp_path):
    write_usd(make_mixed(), tmp_path / "object.usda", units="scene")
    stage = Usd.Stage.Open(str(tmp_path / "object.usda"))
    assert stage.GetRootLayer().customLayerData["rsart:units"] == "scene"
    with pytest.raises(Exception, match="units"):
        write_usd(make_mixed(), tmp_path / "bad.usda", units="cm")


def _textured_twin() -> Twin:
    rng = np.random.default_rng(3)
    base = _box([0.4, 0.4, 0.2], [0, 0, 0.1])
    lid = _box([0.4, 0.4, 0.02], [0, 0, 0.21])
    tex_vis = lid.copy()
    img = Image.fromarray(rng.integers(0, 255, (8, 16, 3), dtype=np.uint8), "RGB")
    uv = rng.uniform(0, 1, (len(tex_vis.vertices), 2))
    tex_vis.visual = trimesh.visual.TextureVisuals(uv=uv, image=img)
    handle = _box([0.05, 0.02, 0.02], [0.15, 0, 0.23])
    handle.visual = trimesh.visual.ColorVisuals(handle, vertex_colors=rng.integers(0, 255, (8, 4), dtype=np.uint8))
    parts = [TwinPart(0, "base", base), TwinPart(1, "lid", lid, visuals=[tex_vis, handle])]
    joints = [Joint("lid_hinge", "revolute", 0, 1, np.array([0.0, 1.0, 0.0]), np.array([-0.2, 0, 0.2]), (0, 1.5))]
    return Twin("box", parts, joints)


def test_textures_written_beside_usda_and_read_back(tmp_path):
    twin = _textured_twin()
    write_usd(twin, tmp_path / "twin" / "object.usda")
    pngs = sorted(p.relative_to(tmp_path / "twin").as_posix() for p in (tmp_path / "twin").rglob("*.png"))
    assert pngs == ["textures/lid_0.png"]
    text = (tmp_path / "twin" / "object.usda").read_text()
    assert "@textures/lid_0.png@" in text  # relative asset path
    back = read_usd(tmp_path / "twin" / "object.usda")
    lid = back.parts[1]
    assert back.parts[0].visuals == []
    assert len(lid.visuals) == 2
    tv, cv = lid.visuals
    src = twin.parts[1].visuals[0]
    np.testing.assert_array_equal(np.asarray(tv.visual.material.image.convert("RGB")),
                                  np.asarray(src.visual.material.image))
    np.testing.assert_allclose(tv.visual.uv, src.visual.uv, atol=1e-7)
    np.testing.assert_array_equal(cv.visual.vertex_colors, twin.parts[1].visuals[1].visual.vertex_colors)
    q = {"lid_hinge": 1.1}
    for a, b in zip(twin.posed_visuals(q)[1], back.posed_visuals(q)[1]):
        assert np.abs(a.vertices - b.vertices).max() < 1e-7
    assert_same_posed(twin, back)


def test_texture_files_mapping_is_referenced_relatively(tmp_path):
    twin = _textured_twin()
    (tmp_path / "twin" / "visual").mkdir(parents=True)
    twin.parts[1].visuals[0].visual.material.image.save(tmp_path / "twin" / "visual" / "lid.png")
    write_usd(twin, tmp_path / "twin" / "object.usda",
              texture_files={1: [str(tmp_path / "twin" / "visual" / "lid.png")]})
    assert not (tmp_path / "twin" / "textures").exists()
    assert "@visual/lid.png@" in (tmp_path / "twin" / "object.usda").read_text()
    # the folder can move: references are relative
    (tmp_path / "twin").rename(tmp_path / "moved")
    back = read_usd(tmp_path / "moved" / "object.usda")
    np.testing.assert_array_equal(np.asarray(back.parts[1].visuals[0].visual.material.image.convert("RGB")),
                                  np.asarray(twin.parts[1].visuals[0].visual.material.image))


def test_write_is_atomic_and_text(tmp_path):
    twin = make_mixed()
    out = tmp_path / "object.usda"
    out.write_text("old")
    write_usd(twin, out)
    assert out.read_text().startswith("#usda 1.0")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["object.usda"]  # no temporary files left
    with pytest.raises(Exception, match=r"\.usda"):
        write_usd(twin, tmp_path / "object.usdc")


def test_write_object_usd_matches_twin(tmp_path):
    """The object folder's twin/object.usda (written by rsart.twin_io) reads back as the same twin."""
    twin_io = pytest.importorskip("rsart.twin_io")
    twin = _textured_twin()
    twin_io.write_object(twin, tmp_path / "box-0000", object_id="box-0000", category="box",
                         source={"kind": "procedural", "id": "t"})
    back = read_usd(tmp_path / "box-0000" / "twin" / "object.usda")
    _assert_same_structure(twin, back, tol=1e-12)
    assert_same_posed(twin, back)


def test_part_without_geometry_roundtrips(tmp_path):
    """A helper part with an empty mesh (as URDF helper links give) survives the round trip."""
    base = _box([0.2, 0.2, 0.2], [0, 0, 0.1])
    cap = trimesh.creation.cylinder(radius=0.05, height=0.04, sections=12)
    cap.apply_translation([0, 0, 0.22])
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    twin = Twin("bottle", [TwinPart(0, "base", base), TwinPart(1, "helper", empty), TwinPart(2, "cap", cap)],
                [Joint("lift", "prismatic", 0, 1, np.array([0, 0, 1.0]), np.zeros(3), (0.0, 0.05)),
                 Joint("twist", "revolute", 1, 2, np.array([0, 0, 1.0]), np.array([0, 0, 0.2]), None)])
    write_usd(twin, tmp_path / "b.usda")
    back = read_usd(tmp_path / "b.usda")
    assert [p.name for p in back.parts] == ["base", "helper", "cap"]
    assert len(back.parts[1].mesh.vertices) == 0
    q = {"lift": 0.03, "twist": 2.0}
    assert np.abs(back.posed_meshes(q)[2].vertices - twin.posed_meshes(q)[2].vertices).max() < 1e-7


@pytest.mark.parametrize("category", ["drawer", "desk_lamp"])
def test_procedural_twins_roundtrip_with_textures(tmp_path, category):
    """rsart's generated twins (textured visuals, chained lamp joints) survive USD unchanged."""
    registry = pytest.importorskip("rsart.sources.procedural.registry")
    twin = registry.generate(category, 1).twin
    write_usd(twin, tmp_path / "object.usda")
    back = read_usd(tmp_path / "object.usda")
    _assert_same_structure(twin, back, tol=1e-12)
    assert_same_posed(twin, back, n=5)
    n_tex = 0
    for pa, pb in zip(twin.parts, back.parts):
        assert len(pb.visuals) == len(pa.visuals)
        for va, vb in zip(pa.visuals, pb.visuals):
            img = getattr(getattr(va.visual, "material", None), "image", None)
            if img is None:
                continue
            n_tex += 1
            got = vb.visual.material.image
            np.testing.assert_array_equal(np.asarray(got), np.asarray(img.convert(got.mode)))
            np.testing.assert_allclose(vb.visual.uv, va.visual.uv, atol=1e-7)
    assert n_tex >= 3


def test_visuals_sharing_an_image_share_one_texture_file(tmp_path):
    twin = _textured_twin()
    lid_vis = twin.parts[1].visuals[0]
    base_vis = twin.parts[0].mesh.copy()
    uv = np.random.default_rng(4).uniform(0, 1, (len(base_vis.vertices), 2))
    base_vis.visual = trimesh.visual.TextureVisuals(uv=uv, image=lid_vis.visual.material.image)  # the same atlas
    twin.parts[0].visuals = [base_vis]
    write_usd(twin, tmp_path / "twin" / "object.usda")
    pngs = sorted(p.relative_to(tmp_path / "twin").as_posix() for p in (tmp_path / "twin").rglob("*.png"))
    assert len(pngs) == 1, pngs
    back = read_usd(tmp_path / "twin" / "object.usda")
    for part in (0, 1):
        np.testing.assert_array_equal(np.asarray(back.parts[part].visuals[0].visual.material.image.convert("RGB")),
                                      np.asarray(lid_vis.visual.material.image))
    np.testing.assert_allclose(back.parts[0].visuals[0].visual.uv, base_vis.visual.uv, atol=1e-7)
