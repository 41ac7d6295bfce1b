"""Broken or hostile USD files: read_usd raises RsartError naming the prim path, never another exception."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from rsart.errors import RsartError, ValidationError
from rsart.usd import read_usd

pytest.importorskip("pxr")

GOOD = """#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Z"
)
def Xform "o" (prepend apiSchemas = ["PhysicsArticulationRootAPI"])
{
    def Xform "base" (prepend apiSchemas = ["PhysicsRigidBodyAPI"])
    {
        def Mesh "m"
        {
            point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
            int[] faceVertexCounts = [4]
            int[] faceVertexIndices = [0, 1, 2, 3]
        }
    }
    def Xform "lid" (prepend apiSchemas = ["PhysicsRigidBodyAPI"])
    {
        double3 xformOp:translate = (0, 0, 1)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        def Mesh "m"
        {
            point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
            int[] faceVertexCounts = [4]
            int[] faceVertexIndices = [0, 1, 2, 3]
        }
    }
    def PhysicsRevoluteJoint "hinge"
    {
        rel physics:body0 = </o/base>
        rel physics:body1 = </o/lid>
        uniform token physics:axis = "Y"
        point3f physics:localPos0 = (0, 0, 1)
        point3f physics:localPos1 = (0, 0, 0)
        quatf physics:localRot0 = (1, 0, 0, 0)
        quatf physics:localRot1 = (1, 0, 0, 0)
        float physics:lowerLimit = 0
        float physics:upperLimit = 90
    }
}
"""

LID_MESH = """            point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
            int[] faceVertexCounts = [4]
            int[] faceVertexIndices = [0, 1, 2, 3]
        }
    }
    def PhysicsRevoluteJoint"""


def _read(tmp_path, text: str, name: str = "bad.usda"):
    p = tmp_path / name
    p.write_text(text)
    return read_usd(p)


def _fails(tmp_path, text: str, *fragments: str) -> RsartError:
    """read_usd must raise RsartError whose message contains every fragment (regex-escaped)."""
    with pytest.raises(RsartError) as ei:
        _read(tmp_path, text)
    msg = str(ei.value)
    for f in fragments:
        assert re.search(re.escape(f), msg), f"{f!r} not in:\n{msg}"
    return ei.value


def test_good_file_reads(tmp_path):
    t = _read(tmp_path, GOOD)
    assert [p.name for p in t.parts] == ["base", "lid"]
    assert t.joint("hinge").limits == pytest.approx((0.0, math.pi / 2))


def test_missing_body_target(tmp_path):
    e = _fails(tmp_path, GOOD.replace("rel physics:body1 = </o/lid>", "rel physics:body1 = </o/nope>"),
               "/o/hinge: body1 targets /o/nope, which does not exist")
    assert isinstance(e, ValidationError)


def test_spherical_joint_is_unsupported(tmp_path):
    text = GOOD.replace("def PhysicsRevoluteJoint", "def PhysicsSphericalJoint")
    _fails(tmp_path, text, "/o/hinge: unsupported joint type PhysicsSphericalJoint")


def test_generic_d6_joint_is_unsupported(tmp_path):
    text = GOOD.replace("def PhysicsRevoluteJoint", "def PhysicsJoint")
    _fails(tmp_path, text, "/o/hinge: unsupported joint type PhysicsJoint")


def test_nan_joint_frame(tmp_path):
    text = GOOD.replace("physics:localPos0 = (0, 0, 1)", "physics:localPos0 = (nan, 0, 1)")
    _fails(tmp_path, text, "/o/hinge: localPos0/localRot0 contain NaN or inf")


def test_inf_mesh_points(tmp_path):
    text = GOOD.replace(LID_MESH, LID_MESH.replace("(1, 1, 0)", "(1, inf, 0)"))
    assert text != GOOD
    _fails(tmp_path, text, "/o/lid/m: mesh points contain NaN or inf")


def test_zero_quaternion(tmp_path):
    text = GOOD.replace("physics:localRot1 = (1, 0, 0, 0)", "physics:localRot1 = (0, 0, 0, 0)")
    _fails(tmp_path, text, "/o/hinge: localRot1 is a zero quaternion")


def test_unknown_axis_token(tmp_path):
    _fails(tmp_path, GOOD.replace('physics:axis = "Y"', 'physics:axis = "W"'),
           "/o/hinge: axis 'W' is not one of X, Y, Z")


def test_mesh_without_points(tmp_path):
    text = GOOD.replace(LID_MESH, LID_MESH.replace("[(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]", "[]"))
    _fails(tmp_path, text, "/o/lid/m: mesh has no points")


def test_face_index_out_of_range(tmp_path):
    text = GOOD.replace(LID_MESH, LID_MESH.replace("[0, 1, 2, 3]", "[0, 1, 2, 7]"))
    _fails(tmp_path, text, "/o/lid/m: faceVertexIndices outside [0, 3]")


def test_body_without_geometry_is_an_empty_part(tmp_path):
    """Not an error: helper links (e.g. a URDF screw joint's helper) are bodies without geometry."""
    base_mesh = ('def Mesh "m"\n        {\n'
                 '            point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]\n'
                 '            int[] faceVertexCounts = [4]\n'
                 '            int[] faceVertexIndices = [0, 1, 2, 3]\n'
                 '        }\n')
    text = GOOD.replace(base_mesh, "", 1)
    assert text != GOOD
    t = _read(tmp_path, text)
    assert len(t.parts[0].mesh.vertices) == 0 and len(t.parts[1].mesh.faces) == 2


def test_invalid_face_counts(tmp_path):
    text = GOOD.replace(LID_MESH, LID_MESH.replace("faceVertexCounts = [4]", "faceVertexCounts = [2, 2]"))
    _fails(tmp_path, text, "/o/lid/m: faceVertexCounts must be >= 3 and sum to len(faceVertexIndices)")


def test_two_roots(tmp_path):
    text = GOOD.replace('def PhysicsRevoluteJoint "hinge"', 'def PhysicsRevoluteJoint "hinge" (active = false)')
    _fails(tmp_path, text, "2 root bodies ['/o/base', '/o/lid']")


def test_joint_cycle(tmp_path):
    extra = """    def Xform "arm" (prepend apiSchemas = ["PhysicsRigidBodyAPI"])
    {
        def Cube "c"
        {
            double size = 0.1
        }
    }
    def PhysicsRevoluteJoint "back"
    {
        rel physics:body0 = </o/arm>
        rel physics:body1 = </o/lid>
    }
    def PhysicsRevoluteJoint "forth"
    {
        rel physics:body0 = </o/lid>
        rel physics:body1 = </o/arm>
    }
}
"""
    text = GOOD.replace("rel physics:body0 = </o/base>\n        rel physics:body1 = </o/lid>",
                        "rel physics:body0 = </o/base>\n        rel physics:body1 = </o/other>")
    text = text.rstrip()[:-1] + """    def Xform "other" (prepend apiSchemas = ["PhysicsRigidBodyAPI"])
    {
        def Sphere "s"
        {
            double radius = 0.1
        }
    }
""" + extra
    _fails(tmp_path, text, "joint cycle: bodies ['/o/lid', '/o/arm'] do not lead back to the root body /o/base")


def test_body_with_two_parent_joints(tmp_path):
    text = GOOD.rstrip()[:-1] + """    def PhysicsPrismaticJoint "slide"
    {
        rel physics:body0 = </o/base>
        rel physics:body1 = </o/lid>
        float physics:lowerLimit = 0
        float physics:upperLimit = 1
    }
}
"""
    _fails(tmp_path, text, "/o/slide: body /o/lid is already body1 of /o/hinge")


def test_prismatic_without_limits(tmp_path):
    text = GOOD.replace("def PhysicsRevoluteJoint", "def PhysicsPrismaticJoint").replace(
        "        float physics:lowerLimit = 0\n        float physics:upperLimit = 90\n", "")
    _fails(tmp_path, text, "/o/hinge: prismatic joint has no finite limits")


def test_one_sided_and_crossed_limits(tmp_path):
    _fails(tmp_path, GOOD.replace("physics:upperLimit = 90", "physics:upperLimit = inf"),
           "/o/hinge: one-sided or infinite limits [0.0, inf]")
    _fails(tmp_path, GOOD.replace("physics:lowerLimit = 0", "physics:lowerLimit = 100"),
           "/o/hinge: lowerLimit 100.0 > upperLimit 90.0")
    _fails(tmp_path, GOOD.replace("physics:lowerLimit = 0", "physics:lowerLimit = nan"),
           "/o/hinge: lowerLimit/upperLimit is NaN")


def test_revolute_joint_to_the_world(tmp_path):
    text = GOOD.replace("        rel physics:body0 = </o/base>\n", "")
    _fails(tmp_path, text, "/o/hinge: revolute joint connects a body to the world")


def test_zero_scale_body(tmp_path):
    text = GOOD.replace('uniform token[] xformOpOrder = ["xformOp:translate"]',
                        'float3 xformOp:scale = (1, 0, 1)\n'
                        '        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:scale"]')
    _fails(tmp_path, text, "/o/lid: degenerate transform (zero scale)")


def test_bad_stage_units(tmp_path):
    _fails(tmp_path, GOOD.replace("metersPerUnit = 1", "metersPerUnit = 0"), "metersPerUnit 0.0 must be a positive")
    _fails(tmp_path, GOOD.replace('upAxis = "Z"', 'upAxis = "X"'), "upAxis 'X' must be Y or Z")


def test_every_problem_is_listed(tmp_path):
    text = GOOD.replace("def PhysicsRevoluteJoint", "def PhysicsSphericalJoint").rstrip()[:-1] + """
    def PhysicsPrismaticJoint "slide"
    {
        rel physics:body0 = </o/base>
        rel physics:body1 = </o/ghost>
    }
}
"""
    e = _fails(tmp_path, text, "2 problems found", "/o/hinge: unsupported joint type",
               "/o/slide: body1 targets /o/ghost")
    assert len(e.problems) == 2


def test_not_a_usd_file(tmp_path):
    with pytest.raises(RsartError, match="bad.usda"):
        _read(tmp_path, "#usda 1.0\n( this is not [ valid usda\n")
    p = tmp_path / "noise.usd"
    p.write_bytes(np.random.default_rng(0).integers(0, 256, 2000, dtype=np.uint8).tobytes())
    with pytest.raises(RsartError, match="noise.usd"):
        read_usd(p)
    with pytest.raises(RsartError, match="file not found"):
        read_usd(tmp_path / "missing.usda")


def test_no_articulation(tmp_path):
    _fails(tmp_path, '#usda 1.0\ndef Xform "empty" {}\n', "no rigid bodies (PhysicsRigidBodyAPI) and no joints")


def test_reference_outside_the_folder_is_refused(tmp_path):
    (tmp_path / "outside.usda").write_text(GOOD)
    inner = tmp_path / "obj"
    inner.mkdir()
    text = '#usda 1.0\ndef Xform "o" (prepend references = @../outside.usda@</o>)\n{\n}\n'
    (inner / "twin.usda").write_text(text)
    with pytest.raises(RsartError, match=r"refers to '\.\./outside\.usda', outside"):
        read_usd(inner / "twin.usda")


def test_wrongly_typed_attributes(tmp_path):
    text = GOOD.replace("point3f physics:localPos0 = (0, 0, 1)", 'string physics:localPos0 = "up"')
    _fails(tmp_path, text, "/o/hinge: localPos0/localRot0 are not a point3f and a quatf")
    text = GOOD.replace(LID_MESH, LID_MESH.replace("int[] faceVertexCounts = [4]", 'string faceVertexCounts = "four"'))
    _fails(tmp_path, text, "/o/lid/m: points/faceVertexCounts/faceVertexIndices are not")
    text = GOOD.replace("float physics:upperLimit = 90", 'string physics:upperLimit = "ninety"')
    _fails(tmp_path, text, "/o/hinge: lowerLimit/upperLimit must be numbers")


def test_non_finite_body_transform(tmp_path):
    text = GOOD.replace("double3 xformOp:translate = (0, 0, 1)", "double3 xformOp:translate = (0, nan, 1)")
    _fails(tmp_path, text, "/o/lid: non-finite transform (NaN or inf)")


def test_joint_without_bodies_and_bad_targets(tmp_path):
    text = GOOD.replace("        rel physics:body0 = </o/base>\n        rel physics:body1 = </o/lid>\n", "")
    _fails(tmp_path, text, "/o/hinge: joint has neither body0 nor body1")
    e = _fails(tmp_path, GOOD.replace("rel physics:body0 = </o/base>", "rel physics:body0 = </>"),
               "not a readable USD file: Relationship target paths must be absolute")  # USD's own parser refuses
    assert "textParserHelpers" not in str(e)
    _fails(tmp_path, GOOD.replace("rel physics:body0 = </o/base>", "rel physics:body0 = </o/base.points>"),
           "/o/hinge: body0 targets /o/base.points, which does not exist")
    _fails(tmp_path, GOOD.replace("rel physics:body0 = </o/base>", "rel physics:body0 = [</o/base>, </o/lid>]"),
           "/o/hinge: body0 has 2 targets; expected one")


def test_texture_outside_the_folder_is_not_read(tmp_path):
    from PIL import Image

    Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(tmp_path / "secret.png")
    (tmp_path / "obj").mkdir()
    text = GOOD.replace(LID_MESH, LID_MESH.replace(
        "int[] faceVertexIndices = [0, 1, 2, 3]",
        "int[] faceVertexIndices = [0, 1, 2, 3]\n"
        "            texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (interpolation = \"vertex\")\n"
        "            rel material:binding = </o/mat>")).rstrip()[:-1] + """
    def Material "mat"
    {
        token outputs:surface.connect = </o/mat/pbr.outputs:surface>
        def Shader "pbr"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </o/mat/tex.outputs:rgb>
            token outputs:surface
        }
        def Shader "tex"
        {
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @../secret.png@
            float3 outputs:rgb
        }
    }
}
"""
    (tmp_path / "obj" / "t.usda").write_text(text.replace('(prepend apiSchemas = ["PhysicsRigidBodyAPI"])\n    {\n'
                                                          '        double3',
                                                          '(prepend apiSchemas = ["PhysicsRigidBodyAPI", '
                                                          '"MaterialBindingAPI"])\n    {\n        double3'))
    with pytest.warns(UserWarning, match="lies outside"):
        t = read_usd(tmp_path / "obj" / "t.usda")
    assert t.parts[1].visuals == []  # geometry kept, texture refused
    # the same file inside the folder is read
    inside = (tmp_path / "obj" / "t.usda").read_text().replace("../secret.png", "ok.png")
    (tmp_path / "obj" / "t.usda").write_text(inside)
    Image.fromarray(np.full((2, 2, 3), 9, np.uint8)).save(tmp_path / "obj" / "ok.png")
    t = read_usd(tmp_path / "obj" / "t.usda")
    assert np.asarray(t.parts[1].visuals[0].visual.material.image)[0, 0, 0] == 9
