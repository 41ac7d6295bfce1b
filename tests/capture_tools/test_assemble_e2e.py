"""End to end: a simulated booth capture (RealSense-like noise), written as raw recordings with the poses
withheld, goes through `rsart capture assemble` to an object folder, which is then checked against the
simulator's truth: camera poses, masks, twin registration, meta.json. Also `rsart perturb --poses colmap`."""
from __future__ import annotations

import json
import sys
import textwrap

import numpy as np
import pytest

from capture_tools.assemble import assemble
from capture_tools.chroma import mask_iou
from capture_tools.pipeline import CaptureSettings
from capture_tools.pose_eval import pose_errors
from capture_tools.raw_writer import write_raw_capture
from rsart.format import read_cameras, read_meta
from rsart.io import read_mask_png

pytestmark = pytest.mark.slow

ROT_TARGET_DEG = 0.5    # the targets, per state (median over the state's views, after Sim(3))
TRANS_TARGET_M = 0.005  # measured 4.1-5.0 mm on m3 (joint, 8 runs; docs/capture.md), so translation is held at
STATE_TRANS_M = 0.0055  # 5.5 mm: the target plus room for the run-to-run variation of multi-threaded SIFT
ONE_FRAME_TRANS_M = 0.0055  # joint mode, one Sim(3) for both states' cameras (measured 4.3-4.9 mm)


@pytest.fixture
def capture_plugin(tmp_path, monkeypatch):
    """Declare the capture tools' entry point the way pyproject.toml does (rsart.commands)."""
    site = tmp_path / "site"
    dist = site / "rsart_capture_test-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: rsart-capture-test\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent("""\
        [rsart.commands]
        capture = capture_tools.cli:register
        """))
    monkeypatch.syspath_prepend(str(site))
    return site


def check_state(out, truth, sid):
    """Pose errors (Sim(3)-aligned and in the object frame as written), mask IoU, part-label accuracy."""
    est = read_cameras(out / "states" / sid / "cameras.json")
    ref = read_cameras(truth / "states" / sid / "cameras.json")
    E, G, iou, acc = [], [], [], []
    for v in est.views:
        g = ref.views[int(v.extra["frame"])]  # raw frames are numbered in the simulator's view order
        E.append(v.c2w)
        G.append(g.c2w)
        pm = read_mask_png(out / "states" / sid / "mask" / f"{v.id}.png")
        gm = read_mask_png(truth / "states" / sid / "mask" / f"{g.id}.png")
        iou.append(mask_iou(pm > 0, gm > 0))
        both = (pm > 0) & (gm > 0)
        acc.append(float((pm[both] == gm[both]).mean()))
    E, G = np.array(E), np.array(G)
    return pose_errors(E, G, "sim3"), pose_errors(E, G, "none"), np.array(iou), np.array(acc)


def poses_of(out, truth, states) -> tuple[np.ndarray, np.ndarray]:
    """(estimated, true) (N, 4, 4) camera-to-world of the given states' assembled views."""
    E, G = [], []
    for sid in states:
        ref = read_cameras(truth / "states" / sid / "cameras.json")
        for v in read_cameras(out / "states" / sid / "cameras.json").views:
            E.append(v.c2w)
            G.append(ref.views[int(v.extra["frame"])].c2w)
    return np.array(E), np.array(G)


def test_frames_layout_end_to_end(sim_capture, tmp_path):
    raw = tmp_path / "raw"
    write_raw_capture(sim_capture, raw, "frames")
    assert not list(raw.rglob("cameras.json")) and not list(raw.rglob("mask"))  # poses and masks withheld
    out = tmp_path / "obj"
    report = assemble(raw, sim_capture, None, out, CaptureSettings(n_views=24, sfm="joint"), progress=lambda *_: None)
    joint = report["joint"]
    assert joint["used"] and joint["registered_per_state"] == {"m0": 24, "m3": 24}
    # cross-state pairs lost their matches off the static base (thinned or dropped); same-state pairs kept all
    pairs = joint["sfm_pairs"]
    assert pairs["thinned"] + pairs["dropped"] > 0 and pairs["kept"] > 0, pairs
    # only the static base ties the states: neither none nor all of a state's object pixels (measured ~0.4 of the
    # closed cabinet, whose lid top moves, and ~0.3 of the open one, whose uncovered body top m0 never saw)
    assert all(0.15 < f < 0.7 for f in joint["static_fraction"].values()), joint["static_fraction"]
    # one frame: the same twin placement for every state
    np.testing.assert_allclose(report["states"]["m0"]["T_world_to_capture"], report["states"]["m3"]["T_world_to_capture"])
    meta = read_meta(out)
    truth_meta = read_meta(sim_capture)
    assert [(s.id, s.kind, s.values) for s in meta.states] == [(s.id, s.kind, s.values) for s in truth_meta.states
                                                              if s.id in ("m0", "m3")]
    assert meta.source["kind"] == "rs-art"
    assert (out / "twin" / "object.urdf").is_file() and all((out / p.mesh).is_file() for p in meta.parts)
    from rsart.cli import main
    assert main(["validate", str(out)]) == 0
    for sid in ("m0", "m3"):
        sim3, frame, iou, acc = check_state(out, sim_capture, sid)
        reg = report["states"][sid]["registration"]
        print(f"\n[{sid}] Sim(3): {sim3.to_dict()}\n[{sid}] object frame: {frame.to_dict()}\n"
              f"[{sid}] mask IoU mean {iou.mean():.4f} min {iou.min():.4f}, part labels {acc.mean():.4f}; "
              f"twin residual {1000 * reg['icp_rmse']:.2f} mm fitness {reg['icp_fitness']:.3f}")
        assert sim3.median_rot_deg < ROT_TARGET_DEG and sim3.median_trans < STATE_TRANS_M
        assert frame.median_rot_deg < 1.0 and frame.median_trans < 0.012  # registration adds a few mm
        assert iou.mean() >= 0.98 and acc.mean() >= 0.98
        assert reg["icp_rmse"] < 0.005 and reg["icp_fitness"] > 0.7
    one = pose_errors(*poses_of(out, sim_capture, ("m0", "m3")), "sim3")
    print(f"one Sim(3) for both states: {one.to_dict()}")
    assert one.median_rot_deg < ROT_TARGET_DEG and one.median_trans < ONE_FRAME_TRANS_M
    rep = json.loads((out / "capture.json").read_text())
    assert set(rep["states"]) == {"m0", "m3"}


def test_video_layout_via_cli(sim_capture, tmp_path, capture_plugin, capsys):
    from rsart.cli import main

    raw = tmp_path / "raw"
    assert main(["capture", "raw", str(sim_capture), "--layout", "video", "--out", str(raw), "--states", "m3"]) == 0
    assert (raw / "m3" / "color.mkv").is_file()  # FFV1, lossless (docs/capture.md has the MJPG figures)
    out = tmp_path / "obj"
    code = main(["capture", "assemble", str(raw), "--twin", str(sim_capture / "twin" / "object.urdf"),
                 "--out", str(out), "--views", "24", "--sfm", "per-state"])
    assert code == 0, capsys.readouterr()
    sim3, frame, iou, acc = check_state(out, sim_capture, "m3")
    print(f"\n[video m3] Sim(3): {sim3.to_dict()}\n[video m3] object frame: {frame.to_dict()}\n"
          f"[video m3] mask IoU {iou.mean():.4f}, part labels {acc.mean():.4f}")
    assert sim3.median_rot_deg < ROT_TARGET_DEG and sim3.median_trans < STATE_TRANS_M
    assert json.loads((out / "capture.json").read_text())["settings"]["sfm"] == "per-state"
    assert frame.median_rot_deg < 1.0 and frame.median_trans < 0.012
    assert iou.mean() >= 0.98
    # refusing to overwrite, and a bad capture log, exit 2 without a traceback
    assert main(["capture", "assemble", str(raw), "--twin", str(sim_capture), "--out", str(out)]) == 2
    (raw / "bad.yaml").write_text("states: [{id: m3, kind: multi, values: {nope: 1}, recording: m3}]\n")
    assert main(["capture", "assemble", str(raw), "--twin", str(sim_capture), "--states", str(raw / "bad.yaml"),
                 "--out", str(tmp_path / "o2")]) == 2
    assert "values" in capsys.readouterr().err


def test_bag_layout_reads_back(sim_capture, tmp_path, capture_plugin, capsys):
    from rsart.cli import main

    raw = tmp_path / "raw"
    write_raw_capture(sim_capture, raw, "bag", states=["m0"])
    assert main(["capture", "info", str(raw / "m0.bag")]) == 0
    info = json.loads(capsys.readouterr().out)
    ref = read_cameras(sim_capture / "states" / "m0" / "cameras.json")
    assert info["frames"] == len(ref.views) and info["intrinsics"] == ref.intrinsics.to_dict()


def test_perturb_with_colmap_poses(sim_capture, tmp_path):
    from rsart.perturb import perturb_object

    out = tmp_path / "colmap"
    summary = perturb_object(sim_capture, out, poses="colmap")
    for sid in ("m0", "m3"):
        est = read_cameras(out / "states" / sid / "cameras.json")
        ref = {v.id: v.c2w for v in read_cameras(sim_capture / "states" / sid / "cameras.json").views}
        e = pose_errors(np.array([v.c2w for v in est.views]), np.array([ref[v.id] for v in est.views]), "none")
        print(f"\n[colmap {sid}] {summary['states'][sid]} -> {e.to_dict()}")
        assert len(est.views) >= 20
        assert e.median_rot_deg < 1.0 and e.median_trans < 0.01
        assert not np.allclose(est.views[0].c2w, ref[est.views[0].id])  # really replaced
    assert read_meta(out).extra["camera_poses"]["source"] == "colmap"


def test_a_broken_reconstruction_is_retried_with_the_next_seed(sim_capture, monkeypatch):
    """SfM under load once returned a depth-reversed ring (every view ~179 degrees off): such an attempt is
    re-run with the next seed and the good attempt is kept; the first attempt here is the real SfM, its
    cameras turned by 180 degrees as that run's were."""
    from capture_tools import object_poses

    real = object_poses._reconstruct
    seeds = []

    def first_reversed(sdir, images, masks, depths, cams, seed):
        seeds.append(seed)
        poses, info = real(sdir, images, masks, depths, cams, seed)
        if len(seeds) == 1:
            flip = np.diag([1.0, -1.0, -1.0, 1.0])  # 180 degrees about each camera's own x axis
            poses = {k: c2w @ flip for k, c2w in poses.items()}
            info["median_rot_deg"] = 180.0
        return poses, info
    monkeypatch.setattr(object_poses, "_reconstruct", first_reversed)
    poses, info = object_poses.estimate_state_poses(sim_capture, "m0", seed=7)
    assert seeds == [7, 8] and info["sfm_attempts"] == 2
    ref = {v.id: v.c2w for v in read_cameras(sim_capture / "states" / "m0" / "cameras.json").views}
    e = pose_errors(np.array(list(poses.values())), np.array([ref[k] for k in poses]), "none")
    assert e.median_rot_deg < 1.0
