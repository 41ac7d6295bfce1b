"""read_usd on articulations authored the way other tools do (Isaac Sim style), not by rsart's writer.

Each file is authored here with the raw pxr API: Y-up or Z-up stages in cm/mm/m, bodies with
random rotated frames (some nested in grouping xforms or inside another body), meshes under nested
scaled xforms, instanced prototypes, guide-purpose collision meshes, joints with random joint frames
and axis tokens, stored under the parent body, and bodies posed at a non-zero joint configuration.
The Twin read back must pose exactly like the same object built directly as a Twin.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from rsart.format import Joint
from rsart.kinematics import Twin, TwinPart
from rsart.usd import Y_UP_TO_Z_UP, read_usd

pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt  # noqa: E402

AXES = {"X": np.array([1.0, 0, 0]), "Y": np.array([0, 1.0, 0]), "Z": np.array([0, 0, 1.0])}


def _box(extents, center) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(center)
    return m


def _T(R=None, t=None, s=None) -> np.ndarray:
    M = np.eye(4)
    if R is not None:
        M[:3, :3] = R
    if s is not None:
        M[:3, :3] = M[:3, :3] @ np.diag(s)
    if t is not None:
        M[:3, 3] = t
    return M


def _gf(M: np.ndarray) -> Gf.Matrix4d:
    return Gf.Matrix4d(M.T.tolist())  # USD matrices act on row vectors


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return trimesh.geometry.align_vectors(a, b)[:3, :3]


# --------------------------------------------------------------------------- the object
# part name -> list of pieces (mesh in its own frame, world rest placement, instanced?)
def make_object():
    handle = _box([0.02, 0.08, 0.02], [0, 0, 0])
    pieces = {
        "base": [(_box([0.6, 0.5, 0.4], [0, 0, 0]), _T(t=[0.1, -0.2, 0.2]), False)],
        "door": [(_box([0.03, 0.45, 0.35], [0, 0, 0]), _T(t=[0.42, -0.2, 0.22]), False),
                 (handle, _T(t=[0.45, -0.38, 0.30]), True),
                 (handle, _T(R=Rotation.from_euler("x", 90, degrees=True).as_matrix(), t=[0.45, -0.38, 0.14]), True)],
        "arm": [(trimesh.creation.icosphere(subdivisions=1, radius=0.04), _T(t=[0.47, 0.0, 0.3]), False)],
        "drawer": [(_box([0.3, 0.3, 0.08], [0, 0, 0]), _T(t=[0.05, -0.25, 0.05]), False)],
        "knob": [(trimesh.creation.cylinder(radius=0.02, height=0.03, sections=12), _T(t=[0.1, -0.2, 0.415]), False)],
    }
    names = list(pieces)

    def unit(v):
        return np.asarray(v, float) / np.linalg.norm(v)

    joints = [
        Joint("door_hinge", "revolute", 0, 1, unit([0.1, 0.2, 1.0]), np.array([0.4, 0.03, 0.05]), (-0.3, 1.9)),
        Joint("arm_elbow", "revolute", 1, 2, unit([1.0, -0.4, 0.3]), np.array([0.45, -0.05, 0.3]), (-2.5, 0.7)),
        Joint("drawer_slide", "prismatic", 0, 3, unit([1.0, 0.3, -0.1]), np.array([0.2, -0.2, 0.05]), (0.0, 0.27)),
        Joint("knob_spin", "revolute", 0, 4, np.array([0.0, 0.0, -1.0]), np.array([0.1, -0.2, 0.4]), None),
    ]
    parts = []
    for i, n in enumerate(names):
        ms = []
        for m, P, _ in pieces[n]:
            m = m.copy()
            m.apply_transform(P)
            ms.append(m)
        offs = np.cumsum([0] + [len(m.vertices) for m in ms[:-1]])
        parts.append(TwinPart(i, n, trimesh.Trimesh(np.vstack([m.vertices for m in ms]),
                                                    np.vstack([m.faces + o for m, o in zip(ms, offs)]),
                                                    process=False)))
    return Twin("foreign", parts, joints), pieces


# --------------------------------------------------------------------------- foreign authoring
def author(twin: Twin, pieces: dict, path, *, up="Y", mpu=0.01, q=None, seed=0, nest_knob=True,
           anchor_to: str | None = None, reverse: tuple[str, ...] = ()) -> None:
    """Write ``twin`` as an Isaac-Sim-like USD at joint values ``q`` (see module docstring)."""
    rng = np.random.default_rng(seed)
    R = Y_UP_TO_Z_UP if up == "Y" else np.eye(3)
    S = _T(R=R.T / mpu)  # rsart world -> stage
    Tq = twin.pose(q or {})
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    UsdGeom.Xform.Define(stage, "/World")
    robot = UsdGeom.Xform.Define(stage, "/World/robot").GetPrim()
    UsdPhysics.ArticulationRootAPI.Apply(robot)
    group = UsdGeom.Xform.Define(stage, "/World/robot/links")
    K = _T(R=Rotation.random(random_state=rng).as_matrix(), t=rng.uniform(-30, 30, 3))  # grouping xform (stage)
    group.AddTransformOp().Set(_gf(K))
    proto = stage.CreateClassPrim("/Prototypes")
    hmesh = None
    G, paths = {}, {}
    for p in twin.parts:
        if p.name == "knob" and nest_knob:
            parent_path, parent_world = paths[0], G[0]
        else:
            parent_path, parent_world = "/World/robot/links", K
        body_path = f"{parent_path}/{p.name}"
        B = _T(R=Rotation.random(random_state=rng).as_matrix(), t=p.mesh.centroid + rng.uniform(-0.1, 0.1, 3))
        W = Tq[p.index] @ B  # body frame in rsart world at q
        G[p.index] = _T(R=R.T @ W[:3, :3], t=R.T @ W[:3, 3] / mpu)  # rigid, stage units
        xf = UsdGeom.Xform.Define(stage, body_path)
        local = np.linalg.inv(parent_world) @ G[p.index]
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*local[:3, 3].tolist()))
        xf.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(
            Gf.Quatd(*np.roll(Rotation.from_matrix(local[:3, :3]).as_quat(), 1).tolist()))
        UsdPhysics.RigidBodyAPI.Apply(xf.GetPrim())
        paths[p.index] = body_path
        Ginv = np.linalg.inv(G[p.index])
        for k, (m, P, inst) in enumerate(pieces[p.name]):
            Pl = Ginv @ S @ Tq[p.index] @ P  # piece frame in body-local stage coordinates (scaled)
            if inst:
                if hmesh is None:
                    hmesh = UsdGeom.Mesh.Define(stage, "/Prototypes/handle/mesh")
                    hmesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(m.vertices.astype(np.float32)))
                    hmesh.CreateFaceVertexCountsAttr([3] * len(m.faces))
                    hmesh.CreateFaceVertexIndicesAttr(m.faces.reshape(-1).tolist())
                ix = UsdGeom.Xform.Define(stage, f"{body_path}/handle_{k}")
                ix.AddTransformOp().Set(_gf(Pl))
                ix.GetPrim().GetReferences().AddInternalReference("/Prototypes/handle")
                ix.GetPrim().SetInstanceable(True)
                continue
            N = _T(R=Rotation.random(random_state=rng).as_matrix(), t=rng.uniform(-5, 5, 3),
                   s=rng.uniform(0.5, 2.0, 3))
            vx = UsdGeom.Xform.Define(stage, f"{body_path}/visuals_{k}")
            vx.AddTransformOp().Set(_gf(Pl @ N))
            mesh = UsdGeom.Mesh.Define(stage, f"{body_path}/visuals_{k}/mesh")
            pts = (np.linalg.inv(N) @ np.c_[m.vertices, np.ones(len(m.vertices))].T).T[:, :3]
            mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)))
            mesh.CreateFaceVertexCountsAttr([3] * len(m.faces))
            faces = m.faces
            if k == 0 and p.index % 2 == 1:  # left-handed winding on some meshes
                mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
                faces = faces[:, [0, 2, 1]]
            mesh.CreateFaceVertexIndicesAttr(faces.reshape(-1).tolist())
        # an Isaac-style collision hull: guide purpose, must not count as geometry
        coll = UsdGeom.Cube.Define(stage, f"{body_path}/collisions")
        coll.CreatePurposeAttr(UsdGeom.Tokens.guide)
        UsdPhysics.CollisionAPI.Apply(coll.GetPrim())
    for j in twin.joints:
        tok = "XYZ"[int(rng.integers(3))]
        spin = Rotation.from_rotvec(AXES[tok] * rng.uniform(-math.pi, math.pi)).as_matrix()
        F = _T(R=_align(AXES[tok], j.axis) @ spin, t=j.origin)  # joint frame, rsart world at rest
        jt = (UsdPhysics.RevoluteJoint if j.type == "revolute" else UsdPhysics.PrismaticJoint).Define(
            stage, f"{paths[j.parent]}/{j.name}")
        jt.CreateAxisAttr(tok)
        rev = j.name in reverse  # authored child-first: body0 = child (the joint value then runs backwards)
        for side, part in ((0, j.child), (1, j.parent)) if rev else ((0, j.parent), (1, j.child)):
            Fq = Tq[part] @ F
            Fs = _T(R=R.T @ Fq[:3, :3], t=R.T @ Fq[:3, 3] / mpu)
            L = np.linalg.inv(G[part]) @ Fs
            rel = jt.CreateBody0Rel() if side == 0 else jt.CreateBody1Rel()
            rel.SetTargets([Sdf.Path(paths[part])])
            (jt.CreateLocalPos0Attr if side == 0 else jt.CreateLocalPos1Attr)(Gf.Vec3f(*L[:3, 3].tolist()))
            qx, qy, qz, qw = Rotation.from_matrix(L[:3, :3]).as_quat()
            (jt.CreateLocalRot0Attr if side == 0 else jt.CreateLocalRot1Attr)(Gf.Quatf(qw, qx, qy, qz))
        if j.limits is not None:
            lo, hi = (np.degrees(j.limits) if j.type == "revolute" else np.asarray(j.limits) / mpu)
            if rev:
                lo, hi = -hi, -lo
            jt.CreateLowerLimitAttr(float(lo))
            jt.CreateUpperLimitAttr(float(hi))
    anchor = UsdPhysics.FixedJoint.Define(stage, "/World/robot/root_joint")
    if anchor_to:  # Isaac style: body0 = a container (not a body), standing for the world
        anchor.CreateBody0Rel().SetTargets([Sdf.Path(anchor_to)])
    anchor.CreateBody1Rel().SetTargets([Sdf.Path(paths[0])])
    UsdPhysics.Scene.Define(stage, "/World/physicsScene")
    ground = UsdGeom.Mesh.Define(stage, "/World/GroundPlane")
    ground.CreatePointsAttr([(-100, -100, 0), (100, -100, 0), (100, 100, 0), (-100, 100, 0)])
    ground.CreateFaceVertexCountsAttr([4])
    ground.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    UsdPhysics.CollisionAPI.Apply(ground.GetPrim())
    stage.SetDefaultPrim(stage.GetPrimAtPath("/World"))
    stage.GetRootLayer().Save()


def compare_by_name(expected: Twin, got: Twin, n: int = 10, seed: int = 1) -> float:
    """Max distance between posed vertices of same-named parts over ``n`` random configurations."""
    assert sorted(p.name for p in got.parts) == sorted(p.name for p in expected.parts)
    assert sorted(got.joint_names) == sorted(expected.joint_names)
    assert got.parts[0].name == expected.parts[0].name  # the static base is part 0
    for j in expected.joints:
        g = got.joint(j.name)
        assert g.type == j.type
        assert got.parts[g.parent].name == expected.parts[j.parent].name
        assert got.parts[g.child].name == expected.parts[j.child].name
        np.testing.assert_allclose(g.axis, j.axis, atol=1e-6)
        if j.limits is None:
            assert g.limits is None
        else:
            np.testing.assert_allclose(g.limits, j.limits, atol=1e-6)
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(n):
        q = {j.name: float(rng.uniform(*(j.limits or (-6.0, 6.0)))) for j in expected.joints}
        em = {p.name: m for p, m in zip(expected.parts, expected.posed_meshes(q))}
        for p, m in zip(got.parts, got.posed_meshes(q)):
            assert np.array_equal(m.faces, em[p.name].faces), p.name
            worst = max(worst, float(np.abs(m.vertices - em[p.name].vertices).max()))
    return worst


@pytest.mark.parametrize("up,mpu,posed,seed,anchor_to", [("Y", 0.01, False, 0, None), ("Y", 0.01, True, 1, "/World"),
                                                         ("Z", 1.0, True, 2, None), ("Z", 0.001, False, 3, "/World")])
def test_foreign_articulation_matches_direct_twin(tmp_path, up, mpu, posed, seed, anchor_to):
    twin, pieces = make_object()
    q = None
    if posed:  # bodies authored away from the rest configuration: the reader must move them back
        q = {"door_hinge": 0.8, "arm_elbow": -1.1, "drawer_slide": 0.2, "knob_spin": 2.5}
    author(twin, pieces, tmp_path / "robot.usda", up=up, mpu=mpu, q=q, seed=seed, anchor_to=anchor_to)
    got = read_usd(tmp_path / "robot.usda")
    assert [p.name for p in got.parts][:2] == ["base", "knob"]  # knob body nested in the base body prim
    worst = compare_by_name(twin, got)
    assert worst < 1e-6, worst  # float32 points/quaternions authored in stage units (measured ~2.5e-7)


def test_hand_computed_y_up_centimetre_door(tmp_path):
    """Independent expectations: a door hinged on the stage's vertical (Y) axis at x = 50 cm."""
    text = """#usda 1.0
(
    metersPerUnit = 0.01
    upAxis = "Y"
)
def Xform "cab" (prepend apiSchemas = ["PhysicsArticulationRootAPI"])
{
    def Xform "frame" (prepend apiSchemas = ["PhysicsRigidBodyAPI"])
    {
        def Mesh "m"
        {
            point3f[] points = [(0, 0, 0), (10, 0, 0), (10, 10, 0), (0, 10, 0)]
            int[] faceVertexCounts = [4]
            int[] faceVertexIndices = [0, 1, 2, 3]
        }
    }
    def Xform "door" (prepend apiSchemas = ["PhysicsRigidBodyAPI"])
    {
        double3 xformOp:translate = (50, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        def Mesh "m"
        {
            point3f[] points = [(0, 0, 0), (50, 0, 0), (50, 100, 0), (0, 100, 0)]
            int[] faceVertexCounts = [4]
            int[] faceVertexIndices = [0, 1, 2, 3]
        }
    }
    def PhysicsRevoluteJoint "hinge"
    {
        rel physics:body0 = </cab/frame>
        rel physics:body1 = </cab/door>
        uniform token physics:axis = "Y"
        point3f physics:localPos0 = (50, 0, 0)
        point3f physics:localPos1 = (0, 0, 0)
        float physics:lowerLimit = 0
        float physics:upperLimit = 90
    }
}
"""
    (tmp_path / "door.usda").write_text(text)
    t = read_usd(tmp_path / "door.usda")
    assert [p.name for p in t.parts] == ["frame", "door"]
    j = t.joint("hinge")
    np.testing.assert_allclose(j.axis, [0, 0, 1], atol=1e-12)  # stage +Y is rsart +Z
    np.testing.assert_allclose(j.origin, [0.5, 0, 0], atol=1e-12)
    np.testing.assert_allclose(j.limits, [0, math.pi / 2], atol=1e-7)
    door = t.posed_meshes({"hinge": math.pi / 2})[1]
    # stage (100, 0, 0) cm -> rsart (1, 0, 0) m at rest; +90 deg about +Z at x=0.5 -> (0.5, 0.5, 0)
    # stage (100, 100, 0) -> rsart (1, 0, 1) at rest -> (0.5, 0.5, 1) when open
    assert len(t.parts[1].mesh.faces) == 2  # the quad was triangulated
    assert np.min(np.linalg.norm(door.vertices - [0.5, 0.5, 0.0], axis=1)) < 1e-9
    assert np.min(np.linalg.norm(door.vertices - [0.5, 0.5, 1.0], axis=1)) < 1e-9


def test_fixed_joint_merges_bodies_and_target_inside_body_resolves(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "m.usda"))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    for name, center in (("base", (0, 0, 0)), ("lid", (0, 0, 1)), ("handle", (0.5, 0, 1))):
        xf = UsdGeom.Xform.Define(stage, f"/o/{name}")
        xf.AddTranslateOp().Set(Gf.Vec3d(*center))
        UsdPhysics.RigidBodyAPI.Apply(xf.GetPrim())
        c = UsdGeom.Cube.Define(stage, f"/o/{name}/geo/cube")
        c.CreateSizeAttr(0.2)
    hinge = UsdPhysics.RevoluteJoint.Define(stage, "/o/hinge")
    hinge.CreateBody0Rel().SetTargets(["/o/base/geo"])  # a prim inside the base body
    hinge.CreateBody1Rel().SetTargets(["/o/lid"])
    hinge.CreateAxisAttr("Y")
    hinge.CreateLocalPos0Attr(Gf.Vec3f(0, 0, 0.5))
    hinge.CreateLocalPos1Attr(Gf.Vec3f(0, 0, -0.5))
    weld = UsdPhysics.FixedJoint.Define(stage, "/o/weld")
    weld.CreateBody0Rel().SetTargets(["/o/lid"])
    weld.CreateBody1Rel().SetTargets(["/o/handle"])
    weld.CreateLocalPos0Attr(Gf.Vec3f(0.5, 0, 0))
    stage.GetRootLayer().Save()
    t = read_usd(tmp_path / "m.usda")
    assert [p.name for p in t.parts] == ["base", "lid"]
    assert len(t.parts[1].mesh.faces) == 24  # lid cube + welded handle cube
    j = t.joint("hinge")
    assert j.limits is None  # no limits authored: unlimited revolute
    np.testing.assert_allclose(j.origin, [0, 0, 0.5], atol=1e-9)
    lid = t.posed_meshes({"hinge": math.pi})[1]
    # handle centre (0.5, 0, 1) turns about +Y through (0, 0, 0.5) by 180 deg -> (-0.5, 0, 0)
    assert np.abs(lid.vertices[8:].mean(0) - [-0.5, 0, 0]).max() < 1e-9


def test_foreign_texture_face_varying(tmp_path):
    from PIL import Image

    img = (np.arange(4 * 4 * 3) * 5 % 256).astype(np.uint8).reshape(4, 4, 3)
    Image.fromarray(img).save(tmp_path / "wood.png")
    stage = Usd.Stage.CreateNew(str(tmp_path / "t.usda"))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    for name, z in (("a", 0.0), ("b", 1.0)):
        xf = UsdGeom.Xform.Define(stage, f"/o/{name}")
        UsdPhysics.RigidBodyAPI.Apply(xf.GetPrim())
        m = UsdGeom.Mesh.Define(stage, f"/o/{name}/m")
        m.CreatePointsAttr([(0, 0, z), (1, 0, z), (1, 1, z), (0, 1, z)])
        m.CreateFaceVertexCountsAttr([4])
        m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    st = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/o/b/m")).CreatePrimvar(
        "uvmap", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    mat = UsdShade.Material.Define(stage, "/o/Looks/wood")
    surf = UsdShade.Shader.Define(stage, "/o/Looks/wood/pbr")
    surf.CreateIdAttr("UsdPreviewSurface")
    rd = UsdShade.Shader.Define(stage, "/o/Looks/wood/uv")
    rd.CreateIdAttr("UsdPrimvarReader_float2")
    rd.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("uvmap")
    tex = UsdShade.Shader.Define(stage, "/o/Looks/wood/tex")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./wood.png")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(rd.ConnectableAPI(), "result")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath("/o/b/m")).Bind(mat)
    j = UsdPhysics.PrismaticJoint.Define(stage, "/o/slide")
    j.CreateBody0Rel().SetTargets(["/o/a"])
    j.CreateBody1Rel().SetTargets(["/o/b"])
    j.CreateAxisAttr("Z")
    j.CreateLowerLimitAttr(0.0)
    j.CreateUpperLimitAttr(0.5)
    stage.GetRootLayer().Save()
    t = read_usd(tmp_path / "t.usda")
    assert t.parts[0].visuals == []
    (vis,) = t.parts[1].visuals
    np.testing.assert_array_equal(np.asarray(vis.visual.material.image.convert("RGB")), img)
    assert vis.visual.uv.shape == (6, 2)  # 2 triangles x 3 corners (faceVarying split per corner)
    # each corner keeps its own UV: corner at (1, 1) has uv (1, 1)
    k = np.where(np.all(np.isclose(vis.vertices, [1, 1, 1]), axis=1))[0]
    np.testing.assert_allclose(vis.visual.uv[k], [[1, 1]] * len(k))
    assert t.joint("slide").limits == (0.0, 0.5)


def test_child_first_joints_are_reoriented_from_the_anchored_base(tmp_path):
    """body0 = child, body1 = parent (value running backwards): read as parent -> child with the axis
    flipped and the same USD limits, i.e. the same physical motion."""
    twin, pieces = make_object()
    author(twin, pieces, tmp_path / "r.usda", q={"arm_elbow": 0.4, "drawer_slide": 0.1}, seed=5,
           reverse=("arm_elbow", "drawer_slide"))
    got = read_usd(tmp_path / "r.usda")
    for name in ("arm_elbow", "drawer_slide"):
        j, g = twin.joint(name), got.joint(name)
        assert got.parts[g.parent].name == twin.parts[j.parent].name
        assert got.parts[g.child].name == twin.parts[j.child].name
        np.testing.assert_allclose(g.axis, -j.axis, atol=1e-6)
        np.testing.assert_allclose(g.limits, [-j.limits[1], -j.limits[0]], atol=1e-6)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = {j.name: float(rng.uniform(*(j.limits or (-6.0, 6.0)))) for j in twin.joints}
        qg = {k: (-v if k in ("arm_elbow", "drawer_slide") else v) for k, v in q.items()}
        em = {p.name: m for p, m in zip(twin.parts, twin.posed_meshes(q))}
        for p, m in zip(got.parts, got.posed_meshes(qg)):
            assert np.abs(m.vertices - em[p.name].vertices).max() < 1e-6
