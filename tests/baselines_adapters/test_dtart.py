"""DTArt adapter: export read back (OpenGL camera-in-object poses, K, depth in mm, masks, GT with floats);
its results folder imported and scored by rsart-eval."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import yaml

import rsart
from baselines_adapters import get_adapter
from tests.baselines_adapters.ba_helpers import (GL_FLIP, backproject_gl, distance_to_mesh, load_ply, play_dtart,
                                                 read_json, score)


@pytest.fixture(scope="module")
def cab_export(objects, tmp_path_factory):
    out = tmp_path_factory.mktemp("dtart") / "cabinet"
    rep = get_adapter("dtart").export(objects["cabinet/two-state"], out)
    return out, rep


def _floats_only(x) -> bool:
    if isinstance(x, dict):
        return all(_floats_only(v) for v in x.values())
    if isinstance(x, list):
        return all(_floats_only(v) for v in x)
    return not isinstance(x, int) or isinstance(x, bool)


def test_export_reads_back(cab_export, objects):
    out, rep = cab_export
    obj = rsart.load(objects["cabinet/two-state"])
    assert rep.protocol == "two-state" and rep.runs["two-state"] == {"start": "m0", "end": "m3"}
    K = np.loadtxt(out / "cam_K.txt")
    kf = yaml.safe_load((out / "init_keyframes.yml").read_text())
    assert len(kf) == 6 and sorted({v["time"] for v in kf.values()}) == [0.0, 1.0]
    gt = {t: load_ply(out / "gt" / k / f"{k}_rotate.ply") for t, k in ((0.0, "start"), (1.0, "end"))}
    views = {0.0: obj.states["m0"].split("train"), 1.0: obj.states["m3"].split("train")}
    n = {0.0: 0, 1.0: 0}
    for key in sorted(kf):
        t = kf[key]["time"]
        v = views[t][n[t]]
        n[t] += 1
        fid = key.replace("frame_", "")
        gl = np.array(kf[key]["cam_in_ob"]).reshape(4, 4)
        np.testing.assert_allclose(gl @ GL_FLIP, v.camera.c2w, atol=1e-12)
        np.testing.assert_allclose(K, v.camera.K)
        depth = cv2.imread(str(out / "depth_filtered" / f"{fid}.png"), cv2.IMREAD_UNCHANGED)
        mask = cv2.imread(str(out / "mask" / f"{fid}.png"), cv2.IMREAD_UNCHANGED)
        rgb = cv2.cvtColor(cv2.imread(str(out / "color_segmented" / f"{fid}.png")), cv2.COLOR_BGR2RGB)
        assert depth.dtype == np.uint16 and mask.dtype == np.uint8
        np.testing.assert_array_equal(mask > 0, v.mask > 0)
        assert not depth[v.mask == 0].any() and not rgb[v.mask == 0].any()
        np.testing.assert_array_equal(depth[v.mask > 0], np.round(v.depth[v.mask > 0] * 1000).astype(np.uint16))
        # DTArt's reading: depth / 1e3, lifted through the OpenGL camera-in-object pose, lies on the GT mesh
        world = backproject_gl(depth / 1e3, gl, K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5)
        assert np.percentile(distance_to_mesh(world, gt[t]), 95) < 2e-3


def test_export_gt_trans_json(cab_export, objects):
    out, _ = cab_export
    trans = read_json(out / "gt" / "trans.json")
    assert _floats_only(trans)  # DTArt's list_to_array drops JSON integers
    lid, drawer = trans["trans_info"]
    assert lid["type"] == "rotate" and lid["rotate"]["r"] == pytest.approx(90.0)
    assert drawer["type"] == "translate" and drawer["translate"]["r"] == pytest.approx(0.25)
    for k in ("start", "end"):
        for f in ("", "static_", "dynamic_0_", "dynamic_1_"):
            assert (out / "gt" / k / f"{k}_{f}rotate.ply").is_file()
    assert read_json(out / "rsart_export.json")["num_parts"] == 3
    assert "--num_parts 3" in (out / "README.txt").read_text()


def test_import_ground_truth_scores_perfect(cab_export, objects, gt_scores, tmp_path):
    out, _ = cab_export
    sub = tmp_path / "dtart.json"
    rep = get_adapter("dtart").import_run(play_dtart(out, tmp_path / "runs" / "exp"), objects["cabinet/two-state"], sub)
    assert rep.parts == ["static", "part_1", "part_2"]
    m, ref = score(sub, objects["cabinet/two-state"])["metrics"], gt_scores["cabinet/two-state"]["metrics"]
    assert m["axis_ang"] < 1e-4 and m["axis_pos"] < 1e-5 and m["type_acc"] == 1.0
    assert m["part_motion_rev"] < 1e-4 and m["part_motion_pri"] < 1e-6
    for k in ("cd_s", "cd_m", "cd_w"):
        assert m[k] <= 1.2 * ref[k] + 1e-6, (k, m[k], ref[k])
    doc = read_json(sub)
    assert doc["method"]["name"] == "DTArt" and doc["method"]["inputs"] == ["rgb", "depth"]
    assert "whole" in doc["results"]["cabinet-0000"]  # init_all.obj / last_all.obj are the whole meshes


def test_import_perturbed_scores_the_known_error(cab_export, objects, tmp_path):
    out, _ = cab_export
    run = play_dtart(out, tmp_path / "exp", perturb={0: {"extra_angle_deg": 7.0}, 1: {"extra_travel": -0.03}})
    sub = tmp_path / "dtart.json"
    get_adapter("dtart").import_run(run, objects["cabinet/two-state"], sub)
    parts = {p["name"]: p["metrics"] for p in score(sub, objects["cabinet/two-state"])["parts"]}
    assert parts["lid"]["part_motion"] == pytest.approx(7.0, abs=1e-6)
    assert parts["lid"]["axis_ang"] < 1e-4 and parts["lid"]["axis_pos"] < 1e-5
    assert parts["drawer"]["part_motion"] == pytest.approx(0.03, abs=1e-9)


def test_replacing_an_entry_keeps_one_entry(cab_export, objects, tmp_path):
    out, _ = cab_export
    sub = tmp_path / "dtart.json"
    ad = get_adapter("dtart")
    ad.import_run(play_dtart(out, tmp_path / "a", perturb={0: {"extra_angle_deg": 7.0}}), objects["cabinet/two-state"], sub)
    ad.import_run(play_dtart(out, tmp_path / "b"), objects["cabinet/two-state"], sub)
    doc = read_json(sub)
    assert list(doc["results"]) == ["cabinet-0000"]
    lid = doc["results"]["cabinet-0000"]["parts"]["part_1"]["joint"]
    assert lid["values"]["m3"] == pytest.approx(math.pi / 2)  # the second import replaced the first


def test_minimum_rotation_threshold_decides_the_type(cab_export, objects, tmp_path):
    """A prismatic part that also rotates by 2° stays prismatic at the default 3° threshold."""
    out, _ = cab_export
    run = play_dtart(out, tmp_path / "exp")
    res = run / "results" / "step_0004000"
    f = res / "init_p01_motion.json"
    d = read_json(f)
    c = math.cos(math.radians(2.0)); s = math.sin(math.radians(2.0))
    d[1]["rotation"] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    f.write_text(__import__("json").dumps(d))
    sub = tmp_path / "s.json"
    get_adapter("dtart").import_run(run, objects["cabinet/two-state"], sub)
    assert read_json(sub)["results"]["cabinet-0000"]["parts"]["part_2"]["joint"]["type"] == "prismatic"
    get_adapter("dtart").import_run(run, objects["cabinet/two-state"], sub, min_rotation_deg=1.0)
    assert read_json(sub)["results"]["cabinet-0000"]["parts"]["part_2"]["joint"]["type"] == "revolute"
