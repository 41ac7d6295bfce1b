"""Backgrounds, sensor outputs, URDF input, contact sheet, Ray backend."""
from __future__ import annotations

import numpy as np
import pytest

from rsart.cli.render import main
from rsart.io import read_depth_png, read_mask_png, read_png_rgb
from rsart.render.booth import booth_meshes
from rsart.render.frame import RenderOptions, StateRenderer
from rsart.render.paths import fit_radius, orbit_pose
from rsart.twin_io import write_object
from rsart.verify import verify

SMALL = ["--size", "160x120", "--no-progress", "--workers", "1"]


def _render(twin, intr, **kw):
    values = {"door_hinge": 0.8, "drawer_slide": 0.1}
    b = twin.bounds(values)
    r = fit_radius(b, intr)
    sr = StateRenderer(twin, values, RenderOptions(intrinsics=intr, rgb_backend="raycast", **kw), b, r)
    return sr.render(orbit_pose(b.mean(0), r, 0.5, 0.7), np.random.default_rng(0))


def test_booth_is_background_in_the_mask_but_seen_by_depth(locker, small_intrinsics):
    f = _render(locker, small_intrinsics, background="booth")
    assert np.all(f.depth > 0)  # floor, curtain and pedestal fill every pixel at 30-60° elevation
    off = f.mask == 0
    green = f.rgb[off].astype(int)
    assert np.mean(green[:, 1] > green[:, 0] + 40) > 0.95  # chroma-key green around the object
    lo = locker.bounds({"door_hinge": 0.8, "drawer_slide": 0.1})
    pedestal = booth_meshes(lo, 1.0)[-1]
    assert pedestal.bounds[1][2] < lo[0][2] and pedestal.extents[0] >= 0.5


def test_transparent_and_random_backgrounds(locker, small_intrinsics):
    t = _render(locker, small_intrinsics, background="transparent")
    assert t.rgb.shape[-1] == 4 and np.array_equal(t.rgb[..., 3] > 0, t.mask > 0)
    r1 = _render(locker, small_intrinsics, background="random")
    assert r1.rgb.shape[-1] == 3 and r1.rgb[r1.mask == 0].std() > 5
    assert np.array_equal(r1.rgb[r1.mask > 0], t.rgb[..., :3][t.mask > 0])  # the object is the same


def test_sensor_keeps_clean_ground_truth(locker, small_intrinsics):
    f = _render(locker, small_intrinsics, background="plain", sensor=True)
    assert f.rgb_clean is not None and not np.array_equal(f.rgb, f.rgb_clean)
    valid = f.depth > 0
    assert 0.5 < valid.sum() / (f.depth_clean > 0).sum() < 1  # some pixels lost, most kept
    assert np.all(f.depth_clean[valid] > 0)
    err = np.abs(f.depth[valid] - f.depth_clean[valid])
    assert 0 < np.median(err) < 0.02


def test_urdf_input_renders_with_sensor_folders(locker, tmp_path):
    src = tmp_path / "src"
    write_object(locker, src, object_id="locker", category="storage", source={"kind": "procedural", "id": "t"},
                 write_usd=False)
    out = tmp_path / "out"
    assert main([str(src / "twin" / "object.urdf"), "--out", str(out), "--protocol", "two-state", "--views", "1",
                 "--test-views", "0", "--sensor", "--rgb-backend", "raycast", *SMALL]) == 0
    obj = out / "object"
    for kind in ("rgb", "depth", "mask", "rgb_clean", "depth_clean"):
        assert (obj / "states" / "m0" / kind / "0000.png").is_file()
    assert read_mask_png(obj / "states/m3/mask/0000.png").max() >= 2
    assert read_depth_png(obj / "states/m3/depth_clean/0000.png").max() > 0
    assert verify(out).ok


def test_contact_sheet(locker, tmp_path):
    from rsart.render.contact_sheet import render_sheet

    src = tmp_path / "src" / "locker"
    write_object(locker, src, object_id="locker", category="storage", source={"kind": "procedural", "id": "t"},
                 write_usd=False)
    out = tmp_path / "out"
    assert main([str(src), "--out", str(out), "--views", "2", "--test-views", "1", "--rgb-backend", "raycast",
                 *SMALL]) == 0
    png = render_sheet(out / "locker", tmp_path / "sheet.png", views_per_state=2, tile_width=100)
    img = read_png_rgb(png)
    rows = 4 * (75 + 2)  # 4 states x (2 views x RGB|depth|mask)
    assert img.shape[0] > rows and img.shape[1:] == (6 * 100, 3)
    assert img[:rows].std() > 20
    # the legend strip below: a swatch in the mask colour of every part, the same colours as the mask tiles
    from rsart.render.contact_sheet import PALETTE, colour_mask

    legend = img[rows:]
    for i in range(len(locker.parts)):
        colour = colour_mask(np.array([[i + 1]], np.uint8))[0, 0]
        assert (np.abs(legend.astype(int) - colour).max(axis=2) == 0).sum() >= 100, i  # a 17x15 swatch
    assert len(PALETTE) > len(locker.parts)


def test_ray_backend(locker, tmp_path):
    ray = pytest.importorskip("ray", reason="ray is an optional extra (pip install ray)")
    src = tmp_path / "src" / "locker"
    write_object(locker, src, object_id="locker", category="storage", source={"kind": "procedural", "id": "t"},
                 write_usd=False)
    ray.init(num_cpus=2, include_dashboard=False)
    try:
        assert main([str(src), "--out", str(tmp_path / "a"), "--views", "2", "--test-views", "0",
                     "--backend", "ray", "--rgb-backend", "raycast", "--size", "160x120", "--no-progress"]) == 0
    finally:
        ray.shutdown()
    assert main([str(src), "--out", str(tmp_path / "b"), "--views", "2", "--test-views", "0",
                 "--rgb-backend", "raycast", *SMALL]) == 0
    for p in sorted((tmp_path / "a" / "locker" / "states").rglob("*.png")):
        q = tmp_path / "b" / p.relative_to(tmp_path / "a")
        assert p.read_bytes() == q.read_bytes()


def test_suite_root_is_rendered_in_place(tmp_path):
    from rsart.format import read_index
    from rsart.sources.procedural.suite import suite_items, write_suite

    root = tmp_path / "synth"
    write_suite(root, workers=1, items=suite_items()[:1])
    before = read_index(root)
    assert main(["--suite", "rsart-synth", "--out", str(root), "--protocol", "two-state", "--views", "1",
                 "--test-views", "0", "--rgb-backend", "raycast", *SMALL]) == 0
    after = read_index(root)
    assert after.objects == before.objects and after.splits["all"] == before.objects
    oid = before.objects[0]
    assert (root / oid / "states" / "m3" / "rgb" / "0000.png").is_file() and verify(root).ok
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "x.txt").write_text("x")
    assert main(["--suite", "rsart-synth", "--out", str(tmp_path / "junk"), *SMALL]) == 2


def test_axis_labels_sit_at_the_pivot_of_a_revolute_axis_and_the_tip_of_a_prismatic_one():
    """A hinge's name goes beside its pivot (the line's ends can lie near other joints: a lamp's
    shoulder line reaches its wrist); a slide's name goes at its arrow's tip."""
    from rsart.camera import Camera, Intrinsics, look_at
    from rsart.render.contact_sheet import draw_axes

    cam = Camera(Intrinsics(640, 480, 600.0, 600.0, 319.5, 239.5), look_at(np.array([0.0, -2.0, 0.0]), np.zeros(3)))
    black = np.zeros((480, 640, 3), np.uint8)
    o, a = np.zeros(3), np.array([1.0, 0.0, 0.0])
    centre = cam.project(o[None])[0][0]
    tip = cam.project((o + 0.8 * a)[None])[0][0]

    def text_near(img, uv, r=14):  # white text pixels (the axis is drawn in red or yellow) near uv
        x, y = int(round(uv[0])), int(round(uv[1]))
        win = img[max(0, y - r):y + r, max(0, x):x + 5 * r]
        return int((win.min(axis=2) > 150).sum())

    hinge = draw_axes(black, cam, {"hinge": (o, a, "revolute")}, 0.8)
    assert text_near(hinge, centre) > 5
    assert text_near(hinge, cam.project((o + 0.4 * a)[None])[0][0]) == 0
    slide = draw_axes(black, cam, {"slide": (o, a, "prismatic")}, 0.8)
    assert text_near(slide, tip) > 5
    assert text_near(slide, centre) == 0
