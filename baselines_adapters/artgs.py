"""ArtGS (Liu et al., ICLR 2025), REArtGS (NeurIPS 2025) and REArtGS++: Gaussian splatting, several
movable parts, two states, part count given; the same output files.

Export (two-state protocol), one scene folder (ArtGS's ``data/<dataset>/<subset>/<scene>``)::

    transforms_{train,test}_{start,end}.json  {camera_angle_x, camera_angle_y, frames: [{file_path:
                                               "start/train/rgba/0000.png", time: 0.0|1.0,
                                               transform_matrix: 4x4 camera-to-world, Blender/OpenGL axes}]}
    {start,end}/{train,test}/rgba/NNNN.png     RGBA, alpha 255 on the object
    {start,end}/{train,test}/depth/NNNN.png    uint16 millimetres, 0 off the object
    num_slots.json                             {"rsart": {<subset>: {<scene>: number of parts incl. static}}}
    gt/trans.json, gt/{start,end}/*_rotate.ply  ground truth (gt_files.py)

``reartgs`` also writes the PARIS-style ``{start,end}/camera_{train,test}.json`` + ``{start,end}/
{train,test}/NNNN.png`` that REArtGS v1 reads.

Import: RUN_DIR is ``outputs/<dataset>/<subset>/<scene>/<model>`` or one ``.../ours_<iter>`` folder (the
highest iteration is used): ``meshes/{start,end}_{-1,0,1..K}.ply`` (−1 whole, 0 static, k movable slot)
and ``joint_info.json`` (per slot: ``hinge`` | ``slider``, axis origin and direction). joint_info.json
carries **no motion amount**, so the adapter estimates each slot's start->end Δ from its two meshes
along the predicted axis (geometry.fit_motion_along_axis: Kabsch when the meshes' vertices correspond,
else a 1-D search minimising the symmetric nearest-neighbour distance). That Δ is the adapter's
estimate, not a number ArtGS reports; the fit residual is logged in the import log.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from rsart.camera import Camera
from rsart.dataset import RSArtObject
from rsart.errors import RsartError
from rsart.format import read_meta
from rsart.io import atomic_dir, read_json, write_json
from rsart.twin_io import read_twin

from .base import PROTOCOL_VIEWS, Adapter, ExportReport, ImportReport
from .geometry import MethodFrame, fit_motion_along_axis, unit
from .gt_files import floats, write_gt
from .images import write_object_depth, write_rgba
from .manifest import write_manifest, write_readme
from .paris import _first_mesh, write_paris_state
from .states import protocol_runs, require_captured
from .submission_io import STATIC, PartOut, write_entry

_OURS = re.compile(r"^ours_(\d+)$")
JOINT_TYPES = {"hinge": "revolute", "slider": "prismatic"}


class ArtGSAdapter(Adapter):
    name = "artgs"
    title = "ArtGS"
    protocol = "two-state"
    inputs = ("rgb", "depth")
    description = "ArtGS (ICLR'25): 3DGS, several movable parts, two states (RGB + depth), part count given"
    run_layout = "outputs/.../<model>/train/ours_<iter>/{meshes/{start,end}_{-1,0..K}.ply, joint_info.json}"
    paris_cameras = False

    def export(self, object_dir: Path, out_dir: Path, *, frame: str = "z-up", overwrite: bool = False,
               subset: str = "synth", **options: Any) -> ExportReport:
        object_dir, out_dir = Path(object_dir), Path(out_dir)
        fr = MethodFrame.named(frame)
        obj = RSArtObject(object_dir)
        run = protocol_runs(obj.meta, self.protocol, object_dir)[0]
        twin = read_twin(object_dir, obj.meta, visuals=False)
        report = ExportReport(self.name, obj.id, out_dir, self.protocol, {"two-state": {"start": run.start.id,
                                                                                      "end": run.end.id}})
        with atomic_dir(out_dir, overwrite=overwrite) as tmp:
            for t, (key, st) in enumerate((("start", run.start), ("end", run.end))):
                views = require_captured(obj, st.id, self.protocol, ("rgb", "depth", "mask"))
                for split in ("train", "test"):
                    sv = [v for v in views if v.split == split]
                    frames = []
                    for i, v in enumerate(sv):
                        rel = f"{key}/{split}/rgba/{i:04d}.png"
                        write_rgba(tmp / rel, v)
                        write_object_depth(tmp / f"{key}/{split}/depth/{i:04d}.png", v)
                        gl = Camera(v.camera.intrinsics, fr.pose_to_method(v.camera.c2w)).c2w_opengl()
                        frames.append({"file_path": rel, "time": float(t), "transform_matrix": floats(gl)})
                    intr = views[0].camera.intrinsics
                    write_json(tmp / f"transforms_{split}_{key}.json", {
                        "camera_angle_x": 2.0 * math.atan(intr.width / (2.0 * intr.fx)),
                        "camera_angle_y": 2.0 * math.atan(intr.height / (2.0 * intr.fy)), "frames": frames})
                    if split == "train":
                        report.views[st.id] = len(sv)
                        if len(sv) < PROTOCOL_VIEWS:
                            report.notes.append(f"state {st.id} has {len(sv)} train views (the paper's protocol "
                                                f"uses {PROTOCOL_VIEWS})")
                intr = views[0].camera.intrinsics
                if abs(intr.cx + 0.5 - intr.width / 2) > 0.5 or abs(intr.cy + 0.5 - intr.height / 2) > 0.5:
                    report.notes.append(f"{st.id}: principal point off the image centre; ArtGS assumes it centred")
                if self.paris_cameras:
                    write_paris_state(obj, st.id, tmp / key, fr, self.protocol,
                                      splits={"train": "train", "test": "test"})
            joints = sorted(obj.meta.joints, key=lambda j: j.child)
            write_gt(tmp / "gt", twin, joints, run.start.values, run.end.values, fr)
            n_slots = len(obj.meta.parts)
            write_json(tmp / "num_slots.json", {"rsart": {subset: {obj.id: n_slots}}})
            write_manifest(tmp, method=self.name, object_id=obj.id, object_dir=object_dir, protocol=self.protocol,
                           frame=frame, runs={"two-state": {"start": run.start.id, "end": run.end.id}},
                           extra={"num_slots": n_slots, "dataset": "rsart", "subset": subset})
            write_readme(tmp, self.readme(obj.id, out_dir, subset, n_slots))
        return report

    def readme(self, oid: str, out_dir: Path, subset: str, n_slots: int) -> str:
        return "\n".join([
            f"{self.title} input for {oid} (two-state protocol). In the {self.title} repository:", "",
            f"mkdir -p data/rsart/{subset} && ln -s {out_dir.resolve()} data/rsart/{subset}/{oid}",
            "python -c \"import json; a=json.load(open('arguments/num_slots.json')); "
            f"a.setdefault('rsart', {{}}).setdefault('{subset}', {{}})['{oid}'] = {n_slots}; "
            "json.dump(a, open('arguments/num_slots.json', 'w'), indent=4)\"",
            f"# then its scripts/train.sh and scripts/render.sh with dataset=rsart subset={subset} scenes=({oid})", "",
            f"then: rsart import --method {self.name} outputs/rsart/{subset}/{oid}/<model> --object {oid} "
            f"--data <ROOT> --into <SUBMISSION>.json"])

    # ------------------------------------------------------------------ import
    def results_dir(self, run_dir: Path) -> Path:
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise RsartError(f"{run_dir}: run folder not found")
        if (run_dir / "joint_info.json").is_file():
            return run_dir
        cands = [p for p in run_dir.rglob("ours_*") if p.is_dir() and _OURS.match(p.name) and not p.is_symlink()
                 and (p / "joint_info.json").is_file()]
        if not cands:
            raise RsartError(f"{run_dir}: no results (expected {self.run_layout})")
        return max(cands, key=lambda p: (int(_OURS.match(p.name).group(1)), str(p)))

    def read_joints(self, path: Path) -> dict[int, tuple[str, np.ndarray, np.ndarray]]:
        """Slot id -> (type, unit axis, origin) in the method frame, from joint_info.json."""
        d = read_json(path)
        if not isinstance(d, list):
            raise RsartError(f"{path}: expected a list of parts")
        out = {}
        for i, e in enumerate(d):
            if not isinstance(e, dict) or not isinstance(e.get("id"), int):
                raise RsartError(f"{path}: entry {i} needs an integer id")
            if e["id"] == 0 or e.get("joint") in ("heavy", "static", "fixed"):
                continue
            jt = JOINT_TYPES.get(e.get("joint"))
            if jt is None:
                raise RsartError(f"{path}: entry {i}: joint {e.get('joint')!r} is not hinge or slider")
            try:
                ax = e["jointData"]["axis"]
                a = unit(np.asarray(ax["direction"], np.float64).reshape(3), f"{path}: entry {i} direction")
                o = np.asarray(ax.get("origin", [0.0, 0.0, 0.0]), np.float64).reshape(3)
            except (KeyError, TypeError, ValueError) as err:
                raise RsartError(f"{path}: entry {i}: malformed jointData.axis ({err})") from None
            out[e["id"]] = (jt, a, o)
        return out

    def import_run(self, run_dir: Path, object_dir: Path, submission: Path, *, frame: str = "z-up",
                   method_version: str | None = None, dataset: dict | None = None, **options: Any) -> ImportReport:
        meta = read_meta(Path(object_dir))
        fr = MethodFrame.named(frame)
        res = self.results_dir(Path(run_dir))
        joints = self.read_joints(res / "joint_info.json")
        start, end = meta.eval_states["start"], meta.eval_states["end"]
        mdir = res / "meshes"
        notes = [f"read {res}"]

        def mesh(key: str, k: int):
            m = _first_mesh(mdir, f"{key}_{k}.ply")
            return fr.mesh_from_method(m) if m is not None else None

        parts = [PartOut(STATIC, {s: m for s, m in ((start, mesh("start", 0)), (end, mesh("end", 0))) if m is not None})]
        for k, (jt, a_m, o_m) in sorted(joints.items()):
            a, o = fr.dirs_from_method(a_m), fr.points_from_method(o_m)
            ms = {s: m for s, m in ((start, mesh("start", k)), (end, mesh("end", k))) if m is not None}
            if start not in ms or end not in ms:
                notes.append(f"part_{k}: meshes start_{k}.ply/end_{k}.ply missing: no motion can be estimated; "
                             f"left out")
                continue
            if jt == "prismatic" and not np.any(o_m):
                o = ms[start].vertices.mean(axis=0)  # ArtGS writes zeros for sliders; any point serves
            fit = fit_motion_along_axis(ms[start], ms[end], jt, a, o)
            notes.append(f"part_{k}: {jt}, Δ={fit.delta:.6g} estimated by {fit.method} from start_{k}.ply/end_{k}.ply "
                         f"(residual {fit.residual:.3g}); joint_info.json has no motion amount")
            parts.append(PartOut(f"part_{k}", ms, {"type": jt, "axis": a, "origin": o,
                                                   "values": {start: 0.0, end: fit.delta}}))
        whole = {s: m for s, m in ((start, mesh("start", -1)), (end, mesh("end", -1))) if m is not None}
        write_entry(Path(submission), meta.object_id, parts, self.method_record(method_version), dataset,
                    whole=whole or None, notes=notes)
        return ImportReport(self.name, meta.object_id, Path(submission), [p.name for p in parts], notes)


class REArtGSAdapter(ArtGSAdapter):
    name = "reartgs"
    title = "REArtGS"
    inputs = ("rgb",)
    description = "REArtGS (NeurIPS'25): ArtGS layout + PARIS-style cameras (v1 reads those); ArtGS outputs"
    paris_cameras = True


class REArtGSPlusPlusAdapter(ArtGSAdapter):
    name = "reartgspp"
    title = "REArtGS++"
    inputs = ("rgb",)
    description = "REArtGS++ (CVPR'26): ArtGS layout and outputs (whole = union of parts)"
