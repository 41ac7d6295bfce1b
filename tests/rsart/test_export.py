"""`rsart export --to nerfstudio|colmap|blender`: each export read back as its tool reads it.

JSON formats: the posed twin is ray cast through the *exported* cameras (read the way nerfstudio /
Blender loaders read them: OpenGL axes, pixel centres at +0.5) and compared with the exported masks.
COLMAP: the model is read with pycolmap and the mesh projected with pycolmap's own camera model.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import rsart
from rsart.cli import main

W, H = 96, 72


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """The conftest cabinet rendered in states m0 and m3 (two-state protocol), 6 train + 2 test views each."""
    from tests.conftest import make_cabinet
    from rsart.twin_io import write_object

    tmp = tmp_path_factory.mktemp("export")
    write_object(make_cabinet(), tmp / "src" / "cabinet-0000", object_id="cabinet-0000", category="storage",
                 source={"kind": "procedural", "id": "test"})
    assert main(["render", str(tmp / "src" / "cabinet-0000"), "--out", str(tmp / "data"), "--protocol", "two-state",
                 "--views", "6", "--test-views", "2", "--size", f"{W}x{H}", "--background", "plain",
                 "--workers", "1", "--no-progress"]) == 0
    return rsart.load(tmp / "data" / "cabinet-0000")


def _raycast_silhouette(obj, sid, fx, fy, cx, cy, w, h, c2w_gl):
    """(h, w) bool: pixels whose ray (through the pixel centre (i + 0.5, j + 0.5), OpenGL camera) hits the posed twin."""
    import open3d as o3d
    import trimesh

    mesh = trimesh.util.concatenate(obj.twin.posed_meshes(obj.states[sid].values))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    d = np.stack([(u - cx) / fx, -(v - cy) / fy, -np.ones_like(u)], -1) @ np.asarray(c2w_gl)[:3, :3].T
    o = np.broadcast_to(np.asarray(c2w_gl)[:3, 3], d.shape)
    rays = np.concatenate([o, d], -1).reshape(-1, 6).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    return np.isfinite(hit).reshape(h, w)


def _iou(a, b):
    return float((a & b).sum()) / max(1, float((a | b).sum()))


def _read_png(path, flags=-1):
    import cv2

    img = cv2.imread(str(path), flags)
    assert img is not None, path
    return img


def test_nerfstudio_export_reprojects_and_keeps_test_views_out(rendered, tmp_path, capsys):
    out = tmp_path / "ns"
    out.mkdir()  # an existing empty folder is accepted
    assert main(["export", str(rendered.path), "--to", "nerfstudio", "--state", "m3", "--out", str(out)]) == 0
    assert "ns-train" in capsys.readouterr().out
    assert [p.name for p in out.iterdir()] == ["m3"]
    d = out / "m3"
    tf = json.loads((d / "transforms.json").read_text())
    st = rendered.states["m3"]
    train_ids = {v.id for v in st.split("train")}
    test_ids = {v.id for v in st.split("test")}
    assert len(tf["train_filenames"]) == 6 and len(tf["test_filenames"]) == 2
    assert not set(tf["train_filenames"]) & (set(tf["test_filenames"]) | set(tf["val_filenames"]))
    assert {f.split("/")[-1][:-4] for f in tf["train_filenames"]} == train_ids
    assert {f.split("/")[-1][:-4] for f in tf["test_filenames"]} == test_ids
    ious = []
    for fr in tf["frames"]:
        assert (d / fr["file_path"]).is_file() and (d / fr["depth_file_path"]).is_file()
        mask = _read_png(d / fr["mask_path"])
        assert mask.ndim == 2 and set(np.unique(mask)) <= {0, 255}  # binary object mask, not part indices
        sil = _raycast_silhouette(rendered, "m3", tf["fl_x"], tf["fl_y"], tf["cx"], tf["cy"], tf["w"], tf["h"],
                                  fr["transform_matrix"])
        ious.append(_iou(sil, mask > 127))
    assert min(ious) > 0.95, ious
    assert (d / tf["ply_file_path"]).is_file()


def test_blender_export_reprojects(rendered, tmp_path):
    out = tmp_path / "bl"
    assert main(["export", str(rendered.path), "--to", "blender", "--all-states", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["m0", "m3"]
    for sid in ("m0", "m3"):
        d = out / sid
        tr = json.loads((d / "transforms_train.json").read_text())
        te = json.loads((d / "transforms_test.json").read_text())
        assert {f["file_path"] for f in tr["frames"]}.isdisjoint(f["file_path"] for f in te["frames"])
        assert len(tr["frames"]) == 6 and len(te["frames"]) == 2
        # a Blender / NeRF-synthetic reader knows only camera_angle_x: focal from it, principal point centred
        f = 0.5 * W / math.tan(0.5 * tr["camera_angle_x"])
        for fr in tr["frames"] + te["frames"]:
            rgba = _read_png(d / (fr["file_path"] + ".png"))
            assert rgba.shape == (H, W, 4)
            sil = _raycast_silhouette(rendered, sid, f, f, W / 2, H / 2, W, H, fr["transform_matrix"])
            assert _iou(sil, rgba[..., 3] > 127) > 0.95


def test_colmap_export_reads_back_with_pycolmap(rendered, tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    out = tmp_path / "cm"
    assert main(["export", str(rendered.path), "--method", "colmap", "--state", "m0", "--out", str(out)]) == 0
    d = out / "m0"
    rec = pycolmap.Reconstruction(str(d / "sparse" / "0"))
    test = pycolmap.Reconstruction(str(d / "test" / "sparse" / "0"))
    st = rendered.states["m0"]
    names = {im.name for im in rec.images.values()}
    assert names == {f"{v.id}.png" for v in st.split("train")}
    assert {im.name for im in test.images.values()} == {f"{v.id}.png" for v in st.split("test")}
    assert sorted(p.name for p in (d / "images").iterdir()) == sorted(names)
    [cam] = rec.cameras.values()
    assert cam.model.name == "PINHOLE" and (cam.width, cam.height) == (W, H)
    assert rec.num_points3D() > 1000
    import trimesh

    mesh = trimesh.util.concatenate(rendered.twin.posed_meshes(st.values))
    pts, _ = trimesh.sample.sample_surface(mesh, 4000, seed=0)
    xyz = np.array([p.xyz for p in rec.points3D.values()])
    # back-projected depth lies on the object's surface
    _, dist, _ = trimesh.proximity.closest_point(mesh, xyz[:: max(1, len(xyz) // 2000)])
    assert np.median(dist) < 0.002
    for im in rec.images.values():
        mask = _read_png(st.dir / "mask" / im.name) > 0
        uv = np.asarray(rec.cameras[im.camera_id].img_from_cam(im.cam_from_world() * pts))
        # COLMAP pixel centres are at +0.5: pixel index = floor(uv)
        ij = np.floor(uv).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
        inside = mask[ij[ok, 1], ij[ok, 0]]
        assert ok.mean() > 0.99 and inside.mean() > 0.97


def _legacy_image_names(images_bin):
    """Image names of a COLMAP images.bin parsed as 3D Gaussian Splatting's read_write_model.py does."""
    import struct

    names = []
    with open(images_bin, "rb") as f:
        (n,) = struct.unpack("<Q", f.read(8))
        for _ in range(n):
            f.read(64)  # image_id, qvec, tvec, camera_id
            name = b""
            while (c := f.read(1)) != b"\x00":
                name += c
            (npts,) = struct.unpack("<Q", f.read(8))
            f.read(24 * npts)
            names.append(name.decode())
        assert f.read() == b""
    return names


def test_colmap_export_parses_as_gaussian_splatting_reads_it(rendered, tmp_path):
    import struct

    out = tmp_path / "cm"
    assert main(["export", str(rendered.path), "--to", "colmap", "--state", "m3", "--out", str(out)]) == 0
    sparse = out / "m3" / "sparse" / "0"
    assert sorted(_legacy_image_names(sparse / "images.bin")) == [f"{v.id}.png" for v in rendered.states["m3"].split("train")]
    with open(sparse / "cameras.bin", "rb") as f:
        n, cam_id, model, w, h = struct.unpack("<QiiQQ", f.read(32))
        params = struct.unpack("<4d", f.read(32))
    K = rendered.states["m3"].cameras.intrinsics
    assert (n, model, w, h) == (1, 1, W, H)  # model 1 = PINHOLE
    assert params == pytest.approx((K.fx, K.fy, K.cx + 0.5, K.cy + 0.5))


def test_export_errors_name_what_exists(rendered, tmp_path, capsys):
    assert main(["export", str(rendered.path), "--to", "colmap", "--state", "m1", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "state 'm1' has no captured views" in err and "m0, m3" in err and "Traceback" not in err
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("x")
    assert main(["export", str(rendered.path), "--to", "blender", "--out", str(tmp_path / "full")]) == 2
    assert "not empty" in capsys.readouterr().err and (tmp_path / "full" / "keep.txt").is_file()
    assert main(["export", str(rendered.path), "--method", "nerfstudio", "--out", str(tmp_path / "ns")]) == 0
    assert (tmp_path / "ns" / "m0" / "transforms.json").is_file()


def test_colmap_without_pycolmap_says_which_extra(rendered, tmp_path):
    """With pycolmap hidden (the [capture] extra missing), one line naming the pip command, exit 2, nothing written."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo / "tests" / "rsart" / "hide_extras"), str(repo)]),
               RSART_HIDE="pycolmap")
    p = subprocess.run([sys.executable, "-m", "rsart", "export", str(rendered.path), "--to", "colmap",
                        "--out", str(tmp_path / "cm")], capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().endswith("pip install 'rsart[capture]'") and not (tmp_path / "cm").exists()


def test_export_refuses_an_image_that_leads_out(rendered, tmp_path, capsys):
    """A symlinked RGB pointing outside the dataset is refused (as the loader refuses it), nothing written."""
    import shutil

    data = tmp_path / "data"
    shutil.copytree(rendered.path.parent, data)
    secret = tmp_path / "secret.png"
    secret.write_bytes(b"not yours")
    victim = data / "cabinet-0000" / "states" / "m0" / "rgb" / "0000.png"
    victim.unlink()
    victim.symlink_to(secret)
    assert main(["export", str(data / "cabinet-0000"), "--to", "colmap", "--state", "m0", "--out", str(tmp_path / "o")]) == 2
    assert "leads out of" in capsys.readouterr().err and not (tmp_path / "o").exists()
