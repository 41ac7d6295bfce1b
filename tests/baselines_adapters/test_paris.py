"""PARIS / ArticulatedGS adapter: export read back in PARIS's conventions; imports scored by rsart-eval."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rsart
from rsart.errors import RsartError
from baselines_adapters import get_adapter
from baselines_adapters.geometry import Z_UP_FROM_Y_UP
from tests.baselines_adapters.ba_helpers import (GL_FLIP, backproject_gl, distance_to_mesh, geodesic_deg_same_angle, inside_fraction, load_ply,
                                                 play_paris, read_json, read_rgba, score)


@pytest.fixture(scope="module")
def cab_export(objects, tmp_path_factory):
    out = tmp_path_factory.mktemp("paris") / "cabinet"
    rep = get_adapter("paris").export(objects["cabinet/single-joint"], out)
    return out, rep


def test_export_layout_and_protocol(cab_export, objects):
    out, rep = cab_export
    assert rep.protocol == "single-joint" and set(rep.runs) == {"lid_hinge", "drawer_slide"}
    man = read_json(out / "rsart_export.json")
    assert man["protocol"] == "single-joint" and man["runs"]["lid_hinge"]["end"] == "s1max"
    meta = rsart.load(objects["cabinet/single-joint"]).meta
    for jn, r in man["runs"].items():
        start, end = meta.state(r["start"]), meta.state(r["end"])
        moving = {k for k in start.values if start.values[k] != end.values[k]}
        assert moving == {jn}  # exactly that joint moves, the others stay fixed
        for key in ("start", "end"):
            for split, n in (("train", 3), ("val", 1), ("test", 1)):
                cams = read_json(out / jn / "load" / key / f"camera_{split}.json")
                assert len(cams) == n + 1 and all((out / jn / "load" / key / split / f"{k}.png").is_file()
                                                  for k in cams if k != "K")
    assert any("100" in n for n in rep.notes)  # fewer views than the paper's protocol is reported


def test_export_cameras_masks_and_gt_agree(cab_export, objects):
    """Poses/intrinsics read back in OpenGL convention equal rsart's; alpha is the mask; the GT mesh projects
    inside the alpha through the exported camera (same frame for cameras and GT)."""
    out, _ = cab_export
    obj = rsart.load(objects["cabinet/single-joint"])
    man = read_json(out / "rsart_export.json")
    for jn, r in man["runs"].items():
        for key in ("start", "end"):
            st = obj.states[r[key]]
            train = st.split("train")
            cams = read_json(out / jn / "load" / key / "camera_train.json")
            K = np.array(cams["K"])
            intr = train[0].camera.intrinsics
            assert K[0, 0] == pytest.approx(intr.fx) and K[0, 2] == pytest.approx(intr.cx + 0.5)
            gt_mesh = load_ply(out / jn / "gt" / key / f"{key}_rotate.ply")
            pts = trimesh.sample.sample_surface(gt_mesh, 2000, seed=0)[0]
            for i, v in enumerate(train):
                gl = np.array(cams[f"{i:04d}"])
                np.testing.assert_allclose(gl @ GL_FLIP, v.camera.c2w, atol=1e-12)
                rgba = read_rgba(out / jn / "load" / key / "train" / f"{i:04d}.png")
                np.testing.assert_array_equal(rgba[..., 3] > 0, v.mask > 0)
                np.testing.assert_array_equal(rgba[..., :3], v.rgb)
                frac = inside_fraction(pts, gl, K[0, 0], K[1, 1], K[0, 2], K[1, 2], rgba[..., 3])
                assert frac > 0.995, (jn, key, i, frac)
                # the capture's depth, lifted through the exported OpenGL camera, lies on the GT mesh
                world = backproject_gl(np.where(v.mask > 0, v.depth, 0), gl, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
                assert np.percentile(distance_to_mesh(world, gt_mesh), 95) < 2e-3
                # ... and the same with the GT in a y-up frame does not: the check tells frames apart
                assert np.median(distance_to_mesh(world @ Z_UP_FROM_Y_UP.T, gt_mesh)) > 0.02


def test_export_gt_joint_in_paris_convention(cab_export, objects):
    """trans.json: z-up frame = rsart world; rotate amounts in degrees, translate in metres; floats only."""
    out, _ = cab_export
    meta = rsart.load(objects["cabinet/single-joint"]).meta
    lid = read_json(out / "lid_hinge" / "gt" / "trans.json")["trans_info"]
    j = meta.joint("lid_hinge")
    assert lid["type"] == "rotate" and isinstance(lid["rotate"]["l"], float)
    assert lid["rotate"]["r"] - lid["rotate"]["l"] == pytest.approx(math.degrees(j.limits[1] - j.limits[0]))
    np.testing.assert_allclose(lid["axis"]["d"], j.axis)
    np.testing.assert_allclose(lid["axis"]["o"], j.origin)
    dr = read_json(out / "drawer_slide" / "gt" / "trans.json")["trans_info"]
    assert dr["type"] == "translate" and dr["translate"]["r"] == pytest.approx(0.25)
    # the static GT of the lid run still holds the drawer (it does not move in that run)
    static = load_ply(out / "lid_hinge" / "gt" / "start" / "start_static_rotate.ply")
    assert len(static.faces) == 24  # base box + drawer box


def test_import_ground_truth_scores_perfect(cab_export, objects, gt_scores, tmp_path):
    out, _ = cab_export
    runs = play_paris(out, tmp_path / "exp")
    sub = tmp_path / "sub" / "paris.json"
    rep = get_adapter("paris").import_run(runs, objects["cabinet/single-joint"], sub)
    assert rep.parts == ["static", "lid", "drawer"]
    r = score(sub, objects["cabinet/single-joint"])
    m, ref = r["metrics"], gt_scores["cabinet/single-joint"]["metrics"]
    assert m["axis_ang"] < 1e-4 and m["axis_pos"] < 1e-5
    assert m["part_motion_rev"] < 1e-4 and m["part_motion_pri"] < 1e-6 and m["type_acc"] == 1.0
    for k in ("cd_s", "cd_m", "cd_w"):  # Chamfer at the sampling floor of the GT reference submission
        assert m[k] <= 1.2 * ref[k] + 1e-6, (k, m[k], ref[k])


def test_import_perturbed_scores_the_known_error(cab_export, objects, tmp_path):
    out, _ = cab_export
    runs = play_paris(out, tmp_path / "exp", perturb={"lid_hinge": {"extra_angle_deg": 5.0, "tilt_deg": 3.0},
                                                      "drawer_slide": {"extra_travel": 0.02}})
    sub = tmp_path / "paris.json"
    get_adapter("paris").import_run(runs, objects["cabinet/single-joint"], sub)
    parts = {p["name"]: p["metrics"] for p in score(sub, objects["cabinet/single-joint"])["parts"]}
    assert parts["lid"]["axis_ang"] == pytest.approx(3.0, abs=1e-6)
    assert parts["lid"]["part_motion"] == pytest.approx(geodesic_deg_same_angle(math.pi / 2, 3.0, math.radians(5.0)),
                                                       abs=1e-5)
    assert parts["drawer"]["part_motion"] == pytest.approx(0.02, abs=1e-9)


def test_flipped_axis_with_negated_angle_is_the_same_motion(cab_export, objects, tmp_path):
    out, _ = cab_export
    runs = play_paris(out, tmp_path / "exp", flip=True)
    sub = tmp_path / "paris.json"
    get_adapter("paris").import_run(runs, objects["cabinet/single-joint"], sub)
    m = score(sub, objects["cabinet/single-joint"])["metrics"]
    assert m["axis_ang"] < 1e-4 and m["part_motion_rev"] < 1e-4 and m["part_motion_pri"] < 1e-6


def test_chained_lamp_runs_merge(objects, gt_scores, tmp_path):
    """Shoulder run moves both arms; elbow run moves arm_2: merged parts and composed end poses are right."""
    out = tmp_path / "lamp"
    get_adapter("paris").export(objects["lamp/single-joint"], out)
    sub = tmp_path / "paris.json"
    get_adapter("paris").import_run(play_paris(out, tmp_path / "exp"), objects["lamp/single-joint"], sub)
    r = score(sub, objects["lamp/single-joint"])
    m, ref = r["metrics"], gt_scores["lamp/single-joint"]["metrics"]
    assert m["axis_ang"] < 1e-4 and m["axis_pos"] < 1e-5 and m["part_motion_rev"] < 1e-4
    for k in ("cd_s", "cd_m", "cd_w"):
        assert m[k] <= 1.2 * ref[k] + 1e-6, (k, m[k], ref[k])


def test_missing_run_leaves_the_part_out(cab_export, objects, tmp_path):
    out, _ = cab_export
    runs = play_paris(out, tmp_path / "exp", skip=("drawer_slide",))
    sub = tmp_path / "paris.json"
    rep = get_adapter("paris").import_run(runs, objects["cabinet/single-joint"], sub)
    assert rep.parts == ["static", "lid"] and any("drawer_slide" in n for n in rep.notes)
    r = score(sub, objects["cabinet/single-joint"])
    assert r["metrics"]["count_acc"] == 0.0 and "drawer" in {p["name"] for p in r["parts"] if p["failures"]}


def test_articulatedgs_motion_json(objects, gt_scores, tmp_path):
    """Unnormalised axis and theta in radians are read correctly."""
    out = tmp_path / "agsexp"
    get_adapter("articulatedgs").export(objects["cabinet/single-joint"], out)
    runs = play_paris(out, tmp_path / "ags", articulatedgs=True)
    sub = tmp_path / "ags.json"
    get_adapter("articulatedgs").import_run(runs, objects["cabinet/single-joint"], sub)
    m = score(sub, objects["cabinet/single-joint"])["metrics"]
    assert m["axis_ang"] < 1e-4 and m["part_motion_rev"] < 1e-4 and m["part_motion_pri"] < 1e-6
    assert read_json(sub)["method"]["name"] == "ArticulatedGS"


def test_export_without_rendered_states_names_the_render_command(cabinet_dir, tmp_path):
    with pytest.raises(RsartError, match="rsart render .* --protocol single-joint"):
        get_adapter("paris").export(cabinet_dir, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_import_rejects_bad_motion_files(cab_export, objects, tmp_path):
    out, _ = cab_export
    runs = play_paris(out, tmp_path / "exp")
    f = next((runs / "lid_hinge").rglob("it20000_test_motion.json"))
    f.write_text('{"type": "rotate", "axis_o": [0, 0, 0], "axis_d": [0, 0, 0], "rot_angle": 10}')
    with pytest.raises(RsartError, match="axis_d"):
        get_adapter("paris").import_run(runs, objects["cabinet/single-joint"], tmp_path / "s.json")
    with pytest.raises(RsartError, match="no run found"):
        get_adapter("paris").import_run(tmp_path, objects["cabinet/single-joint"], tmp_path / "s.json")
