"""Camera conventions, atomic image I/O, checksums."""
import numpy as np
import pytest

from rsart.camera import Camera, Intrinsics, look_at
from rsart.errors import RsartError
from rsart.io import (atomic_dir, read_depth_png, read_mask_png, read_png_rgb, resolve_inside, write_depth_png,
                      write_mask_png, write_png_rgb)
from rsart.verify import verify, write_checksums

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def test_project_and_rays_agree():
    cam = Camera(Intrinsics(40, 30, 35.0, 36.0, 19.5, 14.5), look_at(np.array([0.3, -1.0, 0.6]), np.zeros(3)))
    o, d = cam.rays()
    pts = o[7, 11] + d[7, 11] * 1.3  # pixel (u=11, v=7) at z-depth 1.3
    uv, z = cam.project(pts[None])
    np.testing.assert_allclose(uv[0], [11, 7], atol=1e-9)
    np.testing.assert_allclose(z[0], 1.3, atol=1e-12)
    depth = np.zeros((30, 40))
    depth[7, 11] = 1.3
    np.testing.assert_allclose(cam.backproject(depth)[0], pts, atol=1e-12)


def test_look_at_is_opencv():
    c2w = look_at(np.array([0, -2.0, 0]), np.zeros(3))
    np.testing.assert_allclose(c2w[:3, 2], [0, 1, 0], atol=1e-12)   # z forward, towards the target
    np.testing.assert_allclose(c2w[:3, 1], [0, 0, -1], atol=1e-12)  # y down = world -z
    cam = Camera(Intrinsics(10, 10, 10.0, 10.0, 4.5, 4.5), c2w)
    uv, _ = cam.project(np.array([[0, 0, 0.5]]))  # above the target appears above the image centre
    assert uv[0, 1] < 4.5


def test_opengl_round_trip():
    cam = Camera(Intrinsics(10, 10, 10.0, 10.0, 4.5, 4.5), look_at(np.array([1.0, 2, 3]), np.zeros(3)))
    back = Camera.from_opengl(cam.intrinsics, cam.c2w_opengl())
    np.testing.assert_allclose(back.c2w, cam.c2w)


def test_intrinsics_scaled_keeps_pixel_centres():
    K = Intrinsics(640, 480, 600.0, 600.0, 319.5, 239.5).scaled(160, 120)
    assert (K.fx, K.cx, K.cy) == (150.0, 79.5, 59.5)


def test_png_round_trips(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 255, (5, 7, 3), dtype=np.uint8)
    write_png_rgb(tmp_path / "a.png", rgb)
    np.testing.assert_array_equal(read_png_rgb(tmp_path / "a.png"), rgb)
    depth = np.array([[0.0, 0.5004, 70.0, np.nan]], np.float32)  # 70 m overflows 16-bit mm -> 0
    write_depth_png(tmp_path / "d.png", depth)
    np.testing.assert_allclose(read_depth_png(tmp_path / "d.png"), [[0.0, 0.5, 0.0, 0.0]], atol=1e-7)
    m = np.array([[0, 1, 2]], np.uint8)
    write_mask_png(tmp_path / "m.png", m)
    np.testing.assert_array_equal(read_mask_png(tmp_path / "m.png"), m)
    with pytest.raises(RsartError, match="16-bit"):
        read_depth_png(tmp_path / "m.png")
    assert not list(tmp_path.glob(".*tmp"))


def test_atomic_dir_leaves_nothing_on_failure(tmp_path):
    with pytest.raises(ValueError):
        with atomic_dir(tmp_path / "obj") as d:
            (d / "x").write_text("half")
            raise ValueError("boom")
    assert list(tmp_path.iterdir()) == []


def test_resolve_inside(tmp_path):
    assert resolve_inside(tmp_path, "a/b.ply") == (tmp_path / "a/b.ply").resolve()
    for bad in ("../x", "/etc/passwd", "a/../../x"):
        with pytest.raises(RsartError):
            resolve_inside(tmp_path, bad)
    (tmp_path / "link").symlink_to("/etc")
    with pytest.raises(RsartError, match="leaves"):
        resolve_inside(tmp_path, "link/passwd")


def test_verify_reports_missing_extra_corrupt(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "x.txt").write_text("x")
    (tmp_path / "y.txt").write_text("y")
    (tmp_path / "z.txt").write_text("z")
    write_checksums(tmp_path)
    assert verify(tmp_path).ok and verify(tmp_path).checked == 3
    (tmp_path / "y.txt").write_text("Y")
    (tmp_path / "z.txt").unlink()
    (tmp_path / "new.txt").write_text("n")
    r = verify(tmp_path)
    assert (r.corrupt, r.missing, r.extra) == (["y.txt"], ["z.txt"], ["new.txt"])


def test_copy_folder_contents_refuses_nested_symlinks(tmp_path):
    from rsart.io import copy_folder_contents

    src = tmp_path / "src"
    (src / "twin" / "parts").mkdir(parents=True)
    (src / "meta.json").write_text("{}")
    (src / "twin" / "parts" / "a.ply").write_text("x")
    (src / "states").mkdir()
    copy_folder_contents(src, tmp_path / "out", skip=("states",))
    assert (tmp_path / "out" / "twin" / "parts" / "a.ply").read_text() == "x"
    assert not (tmp_path / "out" / "states").exists()
    (src / "twin" / "parts" / "evil.ply").symlink_to("/etc/hostname")
    with pytest.raises(RsartError, match="symbolic links"):
        copy_folder_contents(src, tmp_path / "out2")
