"""rsart.sources.usd_twin.convert_usd: a foreign USD articulation -> a complete, valid object folder."""
from __future__ import annotations

import json

import numpy as np
import pytest

from rsart.errors import RsartError

pytest.importorskip("pxr")
twin_io = pytest.importorskip("rsart.twin_io")
from rsart.format import validate_path  # noqa: E402
from rsart.sources.usd_twin import convert_usd, default_object_id  # noqa: E402
from tests.rsart.test_usd_foreign import author, compare_by_name, make_object  # noqa: E402


@pytest.fixture
def foreign_usd(tmp_path):
    twin, pieces = make_object()
    src = tmp_path / "src" / "Cabinet Robot.usda"
    src.parent.mkdir()
    author(twin, pieces, src, up="Y", mpu=0.01, q={"door_hinge": 0.5, "drawer_slide": 0.1}, seed=7)
    return twin, src


def test_convert_foreign_usd_to_object_folder(tmp_path, foreign_usd):
    twin, src = foreign_usd
    out = convert_usd(src, tmp_path / "objs" / "cab-0001", object_id="cab-0001", category="storage")
    assert out == tmp_path / "objs" / "cab-0001"
    assert validate_path(out) == []
    meta = json.loads((out / "meta.json").read_text())
    assert meta["source"] == {"kind": "usd", "id": "Cabinet Robot", "file": "Cabinet Robot.usda"}
    assert meta["units"] == "m" and meta["category"] == "storage"
    assert sorted(meta["twin"]) == ["urdf", "usd"]
    kinds = [s["kind"] for s in meta["states"]]
    assert kinds.count("multi") == 4 and "single" in kinds
    # the folder's twin (meta.json + PLY meshes) poses like the object built directly
    back = twin_io.read_twin(out)
    assert compare_by_name(twin, back) < 1e-6
    # and its own USD reads back too
    from rsart.usd import read_usd

    assert compare_by_name(twin, read_usd(out / "twin" / "object.usda")) < 1e-6


def test_defaults_and_overwrite(tmp_path, foreign_usd):
    _, src = foreign_usd
    assert default_object_id(src) == "Cabinet_Robot"
    out = convert_usd(src, tmp_path / "o")
    meta = json.loads((out / "meta.json").read_text())
    assert meta["object_id"] == "Cabinet_Robot" and meta["category"] == "unknown"
    with pytest.raises(RsartError, match="already exists"):
        convert_usd(src, tmp_path / "o")
    convert_usd(src, tmp_path / "o", object_id="other", overwrite=True)
    assert json.loads((out / "meta.json").read_text())["object_id"] == "other"


def test_bad_usd_leaves_nothing(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef PhysicsSphericalJoint "j"\n{\n}\n')
    with pytest.raises(RsartError, match="/j: unsupported joint type PhysicsSphericalJoint"):
        convert_usd(bad, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(RsartError, match="not a USD file"):
        convert_usd(tmp_path / "x.obj", tmp_path / "out")
    with pytest.raises(RsartError, match="not a safe id"):
        convert_usd(bad, tmp_path / "out", object_id="../evil")


def test_textures_survive_conversion(tmp_path):
    from rsart.usd import read_usd, write_usd
    from tests.rsart.test_usd_roundtrip import _textured_twin

    twin = _textured_twin()
    write_usd(twin, tmp_path / "src" / "box.usda")
    out = convert_usd(tmp_path / "src" / "box.usda", tmp_path / "box-0000", category="box")
    assert (out / "twin" / "textures" / "lid_0.png").is_file()  # written by the USD writer beside object.usda
    back = read_usd(out / "twin" / "object.usda")
    img = np.asarray(back.parts[1].visuals[0].visual.material.image.convert("RGB"))
    np.testing.assert_array_equal(img, np.asarray(twin.parts[1].visuals[0].visual.material.image))
    vis = twin_io.read_twin(out).parts[1].visuals  # the folder's OBJ visuals carry a texture too
    assert any(getattr(getattr(v.visual, "material", None), "image", None) is not None for v in vis)


def test_scene_units_are_kept(tmp_path):
    from rsart.usd import write_usd
    from tests.rsart.test_usd_roundtrip import make_mixed

    write_usd(make_mixed(), tmp_path / "pn.usda", units="scene")
    out = convert_usd(tmp_path / "pn.usda", tmp_path / "o")
    assert json.loads((out / "meta.json").read_text())["units"] == "scene"
    write_usd(make_mixed(), tmp_path / "m.usda")
    assert json.loads((convert_usd(tmp_path / "m.usda", tmp_path / "o2") / "meta.json").read_text())["units"] == "m"
