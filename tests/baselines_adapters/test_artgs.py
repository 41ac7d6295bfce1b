"""ArtGS / REArtGS adapters: export read back (Blender transforms, RGBA, depth mm, num_slots, GT);
outputs imported (motion estimated from the meshes) and scored by rsart-eval."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

import rsart
from baselines_adapters import get_adapter
from baselines_adapters.geometry import fit_motion_along_axis
from tests.baselines_adapters.ba_helpers import (GL_FLIP, backproject_gl, distance_to_mesh, load_ply, play_artgs,
                                                 read_json, read_rgba, score)


@pytest.fixture(scope="module")
def cab_export(objects, tmp_path_factory):
    out = tmp_path_factory.mktemp("artgs") / "cabinet-0000"
    rep = get_adapter("artgs").export(objects["cabinet/two-state"], out)
    return out, rep


def test_export_reads_back(cab_export, objects):
    out, rep = cab_export
    obj = rsart.load(objects["cabinet/two-state"])
    assert read_json(out / "num_slots.json") == {"rsart": {"synth": {"cabinet-0000": 3}}}
    for t, (key, sid) in enumerate((("start", "m0"), ("end", "m3"))):
        gt = load_ply(out / "gt" / key / f"{key}_rotate.ply")
        for split in ("train", "test"):
            tf = read_json(out / f"transforms_{split}_{key}.json")
            views = obj.states[sid].split(split)
            assert len(tf["frames"]) == len(views) > 0
            intr = views[0].camera.intrinsics
            assert tf["camera_angle_x"] == pytest.approx(2 * math.atan(intr.width / (2 * intr.fx)))
            fx = intr.width / (2 * math.tan(tf["camera_angle_x"] / 2))  # ArtGS's reading: focal from the FoV
            fy = intr.height / (2 * math.tan(tf["camera_angle_y"] / 2))
            for fr, v in zip(tf["frames"], views):
                assert fr["time"] == float(t) and fr["file_path"].startswith(f"{key}/{split}/rgba/")
                c2w = np.array(fr["transform_matrix"])
                cv = c2w.copy()
                cv[:3, 1:3] *= -1  # ArtGS's own conversion
                np.testing.assert_allclose(cv, v.camera.c2w, atol=1e-12)
                rgba = read_rgba(out / fr["file_path"])
                np.testing.assert_array_equal(rgba[..., 3] > 0, v.mask > 0)
                depth = cv2.imread(str(out / fr["file_path"].replace("rgba", "depth")), cv2.IMREAD_UNCHANGED) / 1e3
                world = backproject_gl(depth, c2w, fx, fy, intr.width / 2, intr.height / 2)
                assert np.percentile(distance_to_mesh(world, gt), 95) < 2e-3


def test_import_ground_truth_scores_perfect(cab_export, objects, gt_scores, tmp_path):
    out, _ = cab_export
    sub = tmp_path / "artgs.json"
    rep = get_adapter("artgs").import_run(play_artgs(out, tmp_path / "model"), objects["cabinet/two-state"], sub)
    assert rep.parts == ["static", "part_1", "part_2"] and any("kabsch" in n for n in rep.notes)
    m, ref = score(sub, objects["cabinet/two-state"])["metrics"], gt_scores["cabinet/two-state"]["metrics"]
    assert m["axis_ang"] < 1e-4 and m["axis_pos"] < 1e-5 and m["type_acc"] == 1.0
    assert m["part_motion_rev"] < 1e-4 and m["part_motion_pri"] < 1e-6
    for k in ("cd_s", "cd_m", "cd_w"):
        assert m[k] <= 1.2 * ref[k] + 1e-6, (k, m[k], ref[k])
    log = read_json(sub.with_name("artgs.import-log.json"))["cabinet-0000"]
    assert any("no motion amount" in n for n in log)


def test_import_perturbed_scores_the_known_error(cab_export, objects, tmp_path):
    """End meshes moved 6° / 0.04 further and the hinge axis tilted 2°: the estimate finds Δ on the tilted axis."""
    out, _ = cab_export
    run = play_artgs(out, tmp_path / "model", perturb={0: {"extra_angle_deg": 6.0}, 1: {"extra_travel": 0.04}})
    sub = tmp_path / "artgs.json"
    get_adapter("artgs").import_run(run, objects["cabinet/two-state"], sub)
    parts = {p["name"]: p["metrics"] for p in score(sub, objects["cabinet/two-state"])["parts"]}
    assert parts["lid"]["part_motion"] == pytest.approx(6.0, abs=1e-4)
    assert parts["drawer"]["part_motion"] == pytest.approx(0.04, abs=1e-6)
    run = play_artgs(out, tmp_path / "model2", perturb={0: {"tilt_deg": 2.0}})
    get_adapter("artgs").import_run(run, objects["cabinet/two-state"], sub)
    parts = {p["name"]: p["metrics"] for p in score(sub, objects["cabinet/two-state"])["parts"]}
    assert parts["lid"]["axis_ang"] == pytest.approx(2.0, abs=1e-6)


def test_motion_from_independent_meshes(cab_export, objects, tmp_path):
    """Start and end meshes without vertex correspondence (re-meshed end): the 1-D search finds Δ."""
    out, _ = cab_export
    run = play_artgs(out, tmp_path / "model", retopologize=True)
    sub = tmp_path / "artgs.json"
    rep = get_adapter("artgs").import_run(run, objects["cabinet/two-state"], sub)
    assert sum("axis-search" in n for n in rep.notes) == 2
    parts = {p["name"]: p["metrics"] for p in score(sub, objects["cabinet/two-state"])["parts"]}
    assert parts["lid"]["part_motion"] < 0.05  # degrees (measured 0.0004)
    assert parts["drawer"]["part_motion"] < 2e-4  # metres (measured 2.5e-5)


def test_fit_motion_sign_and_units():
    """Δ comes back in radians with the sign of the given axis (flipping the axis flips Δ)."""
    import trimesh

    from rsart.kinematics import joint_motion

    box = trimesh.creation.box(extents=[0.3, 0.02, 0.2])
    box.apply_translation([0.15, 0.0, 0.1])
    axis, origin = np.array([0.0, 0.0, 1.0]), np.zeros(3)
    end = box.copy()
    end.apply_transform(joint_motion("revolute", axis, origin, 0.7))
    assert fit_motion_along_axis(box, end, "revolute", axis, origin).delta == pytest.approx(0.7, abs=1e-9)
    assert fit_motion_along_axis(box, end, "revolute", -axis, origin).delta == pytest.approx(-0.7, abs=1e-9)
    v, f = trimesh.remesh.subdivide_to_size(end.vertices, end.faces, max_edge=0.02)
    fit = fit_motion_along_axis(box, trimesh.Trimesh(v, f), "revolute", axis, origin)
    assert fit.method == "axis-search" and fit.delta == pytest.approx(0.7, abs=math.radians(0.2))


def test_reartgs_also_writes_paris_cameras(objects, tmp_path):
    out = tmp_path / "re"
    get_adapter("reartgs").export(objects["cabinet/two-state"], out)
    cams = read_json(out / "start" / "camera_train.json")
    obj = rsart.load(objects["cabinet/two-state"])
    v = obj.states["m0"].split("train")[0]
    np.testing.assert_allclose(np.array(cams["0000"]) @ GL_FLIP, v.camera.c2w, atol=1e-12)
    assert (out / "start" / "train" / "0000.png").is_file() and (out / "transforms_train_start.json").is_file()
