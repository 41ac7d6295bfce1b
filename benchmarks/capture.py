"""Benchmark: camera-pose accuracy of `rsart capture assemble`, per-state SfM vs joint SfM (targets: median
rotation < 0.5°, translation < 5 mm per state), with the object-mask IoU and the twin registration residual.

Input: the capture simulator renders the textured test cabinet (tests/capture_tools/textured_twin.py; twin
texture seeds ``--twins``) in the green booth with the RealSense-like sensor model, states m0 (closed) and
m3 (open), 24 views per state at 320 x 240; the frame-folder raw layout is written with the poses and masks
withheld and assembled with ``--views 24`` in each SfM mode, ``--repeats`` times (SIFT extraction and
open3d RANSAC are multi-threaded, so reruns differ a little). Pose errors are against the simulator's
true poses: per state after one Sim(3) per state, for the whole capture after one Sim(3) for all states
(what a shared frame must satisfy), and in the object frame as written (no alignment).

    python benchmarks/capture.py [--twins 0 1] [--repeats 2] [--out benchmarks/results/capture.json]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("MUJOCO_GL", os.environ["PYOPENGL_PLATFORM"])

import numpy as np  # noqa: E402

from capture_tools.assemble import assemble  # noqa: E402
from capture_tools.chroma import mask_iou  # noqa: E402
from capture_tools.pipeline import CaptureSettings  # noqa: E402
from capture_tools.pose_eval import pose_errors  # noqa: E402
from capture_tools.raw_writer import write_raw_capture  # noqa: E402
from rsart.format import read_cameras  # noqa: E402
from rsart.io import read_mask_png  # noqa: E402

from common import REPO, machine, write_result  # noqa: E402

STATES = ("m0", "m3")
ROT_TARGET_DEG, TRANS_TARGET_M = 0.5, 0.005


def simulate(out: Path, twin_seed: int) -> Path:
    """Render the textured cabinet (texture seed ``twin_seed``) as the capture tests do; returns the object folder."""
    from rsart.camera import REALSENSE_D435_COLOR_640x480
    from rsart.render.frame import RenderOptions
    from rsart.render.runner import RenderJob, render_object_dir
    from rsart.twin_io import write_object
    from tests.capture_tools.textured_twin import make_textured_cabinet

    obj = out / f"cabinet-{twin_seed:04d}"
    write_object(make_textured_cabinet(twin_seed), obj, object_id=obj.name, category="storage",
                 source={"kind": "procedural", "id": "textured-cabinet"})
    K = REALSENSE_D435_COLOR_640x480.scaled(320, 240)
    job = RenderJob(protocol="two-state", views=24, test_views=0,
                    options=RenderOptions(intrinsics=K, sensor=True, background="booth"))
    render_object_dir(obj, job, workers=1, progress=False)
    return obj


def measure(out: Path, truth: Path, report: dict) -> dict:
    """Pose errors (per state, whole capture, object frame), mask IoU and twin residual of an assembled folder."""
    res: dict = {"states": {}}
    E_all, G_all = [], []
    for sid in STATES:
        est = read_cameras(out / "states" / sid / "cameras.json")
        ref = read_cameras(truth / "states" / sid / "cameras.json")
        E, G, iou = [], [], []
        for v in est.views:
            g = ref.views[int(v.extra["frame"])]
            E.append(v.c2w)
            G.append(g.c2w)
            iou.append(mask_iou(read_mask_png(out / "states" / sid / "mask" / f"{v.id}.png") > 0,
                                read_mask_png(truth / "states" / sid / "mask" / f"{g.id}.png") > 0))
        E_all += E
        G_all += G
        sim3, frame = pose_errors(np.array(E), np.array(G), "sim3"), pose_errors(np.array(E), np.array(G), "none")
        reg = report["states"][sid]["registration"]
        res["states"][sid] = {"views": len(E), "median_rot_deg": sim3.median_rot_deg, "median_trans_m": sim3.median_trans,
                              "sim3_scale": sim3.scale, "object_frame_median_rot_deg": frame.median_rot_deg,
                              "object_frame_median_trans_m": frame.median_trans, "mask_iou_mean": float(np.mean(iou)),
                              "twin_residual_m": reg["icp_rmse"], "twin_fitness": reg["icp_fitness"]}
    one = pose_errors(np.array(E_all), np.array(G_all), "sim3")
    frame = pose_errors(np.array(E_all), np.array(G_all), "none")
    res["capture"] = {"views": len(E_all), "one_sim3_median_rot_deg": one.median_rot_deg,
                      "one_sim3_median_trans_m": one.median_trans, "object_frame_median_rot_deg": frame.median_rot_deg,
                      "object_frame_median_trans_m": frame.median_trans}
    res["meets_targets_per_state"] = all(s["median_rot_deg"] < ROT_TARGET_DEG and s["median_trans_m"] < TRANS_TARGET_M
                                         for s in res["states"].values())
    if "joint" in report:
        res["joint"] = {k: report["joint"][k] for k in ("used", "static_fraction") if k in report["joint"]}
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--twins", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "capture.json")
    args = ap.parse_args()
    runs = []
    with tempfile.TemporaryDirectory(prefix="rsart-bench-capture-") as tmp:
        tmp = Path(tmp)
        for seed in args.twins:
            truth = simulate(tmp, seed)
            raw = tmp / f"raw-{seed}"
            write_raw_capture(truth, raw, "frames")
            for rep in range(args.repeats):
                for mode in ("per-state", "joint"):
                    out = tmp / f"obj-{seed}-{mode}-{rep}"
                    t0 = time.perf_counter()
                    report = assemble(raw, truth, None, out, CaptureSettings(n_views=24, sfm=mode), progress=lambda *_: None)
                    dt = time.perf_counter() - t0
                    r = {"twin_seed": seed, "repeat": rep, "sfm": mode, "seconds": dt, **measure(out, truth, report)}
                    runs.append(r)
                    s = r["states"]
                    print(f"twin {seed} run {rep} {mode:9s}: " + ", ".join(
                        f"{k} {v['median_rot_deg']:.3f}° {1000 * v['median_trans_m']:.2f} mm" for k, v in s.items())
                        + f"; one Sim(3) {r['capture']['one_sim3_median_rot_deg']:.3f}° "
                        f"{1000 * r['capture']['one_sim3_median_trans_m']:.2f} mm; {dt:.0f} s", flush=True)
    summary = {}
    for mode in ("per-state", "joint"):
        rs = [r for r in runs if r["sfm"] == mode]
        summary[mode] = {"runs": len(rs), "runs_meeting_targets_per_state": sum(r["meets_targets_per_state"] for r in rs),
                         "worst_state_median_rot_deg": max(s["median_rot_deg"] for r in rs for s in r["states"].values()),
                         "worst_state_median_trans_m": max(s["median_trans_m"] for r in rs for s in r["states"].values())}
    write_result(args.out, {"benchmark": "capture poses, per-state vs joint SfM", "targets": {
        "median_rot_deg": ROT_TARGET_DEG, "median_trans_m": TRANS_TARGET_M}, "machine": machine(),
        "summary": summary, "runs": runs})
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
