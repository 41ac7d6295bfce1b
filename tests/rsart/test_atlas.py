"""A part's visual meshes merged into one textured mesh keep their colours, through the written OBJ."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image

from rsart.atlas import MAX_TILED_SIDE, merge_visuals
from rsart.format import Joint
from rsart.kinematics import Twin, TwinPart
from rsart.twin_io import read_twin, write_object

pytest.importorskip("open3d")  # Albedo lives in the render module
from rsart.render.raster import Albedo  # noqa: E402


def _colours(meshes: list[trimesh.Trimesh]) -> np.ndarray:
    """(F, 3) base colour at every face's centroid, as the ray-cast renderer samples it."""
    return np.concatenate([Albedo.of(m).sample(np.arange(len(m.faces)), np.full((len(m.faces), 2), 1 / 3))
                           for m in meshes])


def _textured(mesh: trimesh.Trimesh, image: np.ndarray, uv: np.ndarray, diffuse) -> trimesh.Trimesh:
    mesh = mesh.copy()
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.SimpleMaterial(
        image=Image.fromarray(image), diffuse=np.asarray(diffuse, np.uint8)))
    return mesh


def _meshes() -> list[trimesh.Trimesh]:
    rng = np.random.default_rng(0)
    box = trimesh.creation.box((0.2, 0.1, 0.05))
    checker = np.kron(np.array([[1, 0], [0, 1]]), np.ones((4, 4)))[..., None] * [200, 40, 40] + [20, 20, 120]
    checker = checker.astype(np.uint8)
    # 1: a checker texture at half intensity (diffuse 128) in [0, 1]; 2: the same repeated 3 x 2 times;
    # 3: repeated 400 times (more than MAX_TILED_SIDE px): its mean colour; 4: face colours; 5: a
    # material colour with no UVs
    m1 = _textured(box, checker, rng.random((len(box.vertices), 2)), [128, 128, 128, 255])
    m2 = _textured(box.copy().apply_translation((0.3, 0, 0)), checker,
                   rng.random((len(box.vertices), 2)) * [3, 2] - [1, 0], [255, 255, 255, 255])
    m3 = _textured(box.copy().apply_translation((0.6, 0, 0)), checker,
                   rng.random((len(box.vertices), 2)) * [MAX_TILED_SIDE, 1], [255, 255, 255, 255])
    m4 = box.copy().apply_translation((0.9, 0, 0))
    m4.visual = trimesh.visual.ColorVisuals(m4, face_colors=rng.integers(0, 256, (len(m4.faces), 4)).astype(np.uint8))
    m5 = box.copy().apply_translation((1.2, 0, 0))
    m5.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.SimpleMaterial(
        diffuse=np.array([204, 163, 40, 255], np.uint8)))
    return [m1, m2, m3, m4, m5]


def test_merged_meshes_keep_every_faces_colour():
    meshes = _meshes()
    merged = merge_visuals(meshes)
    assert len(merged.faces) == sum(len(m.faces) for m in meshes)
    truth, got = _colours(meshes), _colours([merged])
    n3 = sum(len(m.faces) for m in meshes[:2])
    keep = np.ones(len(truth), bool)
    keep[n3:n3 + len(meshes[2].faces)] = False  # the 400-times repeated texture: compared with its mean below
    assert np.abs(got[keep] - truth[keep]).max() < 1.5 / 255
    tex = np.asarray(meshes[2].visual.material.image.convert("RGB"), np.float64) / 255
    assert np.abs(got[~keep] - tex.reshape(-1, 3).mean(axis=0)).max() < 1.5 / 255
    # the old packing (trimesh's concatenate) darkened and scrambled them
    packed = _colours([trimesh.util.concatenate([m.copy() for m in meshes])])
    assert np.abs(packed[keep] - truth[keep]).max() > 0.2


def test_written_part_visual_renders_in_its_source_colours(tmp_path):
    base = TwinPart(0, "base", trimesh.creation.box((0.3, 0.3, 0.3)))
    lid = TwinPart(1, "lid", trimesh.creation.box((0.3, 0.3, 0.02)).apply_translation((0, 0, 0.2)),
                   visuals=_meshes()[:2])
    twin = Twin("box", [base, lid], [Joint("hinge", "revolute", 0, 1, np.array([1.0, 0, 0]), np.zeros(3), (0.0, 1.0))])
    write_object(twin, tmp_path / "o", object_id="o", category="box", source={"kind": "procedural", "id": "t"},
                 write_usd=False)
    back = read_twin(tmp_path / "o")
    truth, got = _colours(lid.visuals), _colours(back.parts[1].render_meshes())
    assert np.abs(got - truth).max() < 1.5 / 255


def test_partnet_visuals_keep_their_colours(partnet_root, tmp_path):
    """Real PartNet-Mobility parts (tens of meshes each, repeating swatch textures, colour-only materials)."""
    from rsart.sources.partnet import read_partnet

    for oid in ("101940", "8867"):
        twin, *_ = read_partnet(partnet_root / oid)
        write_object(twin, tmp_path / oid, object_id=oid, category="c", source={"kind": "partnet-mobility", "id": oid},
                     write_usd=False)
        back = read_twin(tmp_path / oid)
        for p0, p1 in zip(twin.parts, back.parts):
            truth = _colours([m for m in p0.render_meshes() if len(m.faces)])
            got = _colours([m for m in p1.render_meshes() if len(m.faces)])
            err = np.abs(got - truth).max(axis=1)
            assert np.mean(err > 0.05) < 0.01, (oid, p0.name, float(np.mean(err > 0.05)))
