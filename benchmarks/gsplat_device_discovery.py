"""GPU check of PD²GS end to end on the gsplat backend: train one object's field and run the articulated
discovery (stage 1 -> initialisation -> fit -> model selection) with ``backend="gsplat"``, then the same
discovery from the same field with the ``cpu`` backend, and print each run's joints against the ground truth
and its times.

Meshes are left out (``pd2gs.discovery.meshing`` needs open3d, whose 105 MB wheel cannot travel to the lent
machine), so this scores the joints only, with rsart's own metric functions (:mod:`rsart.metrics.joints`),
each true joint against the predicted joint of the smallest axis angle (a check, not the benchmark's
matching). Writes ``--out``/gsplat-discovery.json, one key per stage, rewritten after each (atomic).

    python benchmarks/gsplat_device_discovery.py --data <object folder> --work <scratch> --out <dir>

Run it on a CUDA machine through ``benchmarks/gsplat_device_check.sh`` (``DISCOVERY_DATA`` names the object).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _save(path: Path, doc: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=1, default=float))
    os.replace(tmp, path)


def joint_report(joints: dict, start: str, end: str, obj) -> list[dict]:
    """Per true movable joint: the predicted joint (``joints``: body -> JointFit) of the smallest axis angle
    and its errors."""
    from rsart.metrics.joints import JointEstimate, joint_errors

    ev = obj.meta.eval_states
    vs, ve = obj.meta.state(ev["start"]).values, obj.meta.state(ev["end"]).values
    axes = obj.twin.posed_axes(vs)
    preds = {f"p{b}": jf.estimate(start, end) for b, jf in joints.items()}
    out = []
    for j in obj.twin.joints:
        if j.type not in ("revolute", "prismatic"):
            continue
        o, a = axes[j.name]
        true = JointEstimate.make(j.type, a, o, ve[j.name] - vs[j.name])
        errs = {name: joint_errors(p, true) for name, p in preds.items()}
        best = min(errs, key=lambda n: errs[n]["axis_ang"]) if errs else None
        out.append({"joint": j.name, "type": j.type, "pred": best,
                    "pred_type": preds[best].type if best else None, **(errs[best] if best else {})})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="one rendered object folder (meta.json)")
    ap.add_argument("--work", required=True, help="scratch folder for the trained field")
    ap.add_argument("--out", required=True)
    ap.add_argument("--iters", type=int, default=None, help="training iterations (default: TrainConfig's)")
    ap.add_argument("--backend", default="gsplat", help="render backend of training and the first discovery")
    ap.add_argument("--quick", action="store_true",
                    help="a smoke test of this script: few fit steps, one start, no polish (not a measurement)")
    ap.add_argument("--cpu-discovery", action="store_true", help="also run discovery with the cpu backend")
    args = ap.parse_args()

    import torch

    import rsart
    from pd2gs.config import TrainConfig
    from pd2gs.discovery.config import DiscoveryConfig
    from pd2gs.discovery.pipeline import articulated_parts, stage1
    from pd2gs.render.gsplat_backend import gsplat_status
    from pd2gs.train import train_object

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc_path = out / "gsplat-discovery.json"
    doc: dict = {"device": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
                 "torch": torch.__version__, "threads": torch.get_num_threads(),
                 "gsplat_unavailable": gsplat_status()}
    obj = rsart.load(args.data)
    tcfg = TrainConfig(backend=args.backend)
    if args.iters:
        tcfg = dataclasses.replace(tcfg, iters=args.iters)
    t0 = time.perf_counter()
    model = train_object(Path(args.data), Path(args.work) / "run", tcfg, progress=False)
    metrics = json.loads((Path(args.work) / "run" / "metrics.json").read_text())
    doc["train"] = {"seconds": time.perf_counter() - t0, "iters": tcfg.iters, **metrics}
    print("train:", json.dumps(doc["train"]), flush=True)
    _save(doc_path, doc)

    for backend in [args.backend] + (["cpu"] if args.cpu_discovery and args.backend != "cpu" else []):
        cfg = DiscoveryConfig(render_backend=backend, background=model.background)
        if args.quick:
            cfg = dataclasses.replace(cfg, starts="kabsch", fit_iters=30, select_iters=10, select_rounds=1,
                                      final_iters=10, polish_iters=0)
        t0 = time.perf_counter()
        d = stage1(model, obj, cfg)
        articulated_parts(d)
        secs = time.perf_counter() - t0
        rec = {"seconds": secs, "test_loss": d.diag.get("test_loss"), "tree": d.diag.get("tree"),
               "fitted": {f"p{b}": jf.to_submission() for b, jf in d.joints.items()},
               "starts": d.diag.get("starts"), "select_log": d.diag.get("select", {}).get("log")}
        try:
            rec["joints"] = joint_report(d.joints, d.start, d.end, obj)
        except Exception as e:  # keep the run's raw joints even if the report breaks
            rec["joints_error"] = f"{type(e).__name__}: {e}"
        doc[f"discovery_{backend}"] = rec
        print(f"discovery [{backend}]:", json.dumps(doc[f"discovery_{backend}"], default=float), flush=True)
        _save(doc_path, doc)


if __name__ == "__main__":
    main()
