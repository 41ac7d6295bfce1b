"""DTArt — "Neural Implicit Representation for Building Digital Twins of Unknown Articulated Objects"
(Weng et al., CVPR 2024): multi-part, two states, RGB-D, part count given.

Export (two-state protocol: the object's eval start and end states, the train views of each), one
instance folder::

    cam_K.txt                 3x3 intrinsics (OpenCV pixel convention, as rsart stores them)
    init_keyframes.yml        frame_NNNNN: {cam_in_ob: 16 floats (OpenGL camera-to-object), time: 0.0|1.0}
    color_segmented/NNNNN.png RGB, background black
    depth_filtered/NNNNN.png  uint16 millimetres, 0 off the object
    mask/NNNNN.png            255 on the object
    gt/                       trans.json + {start,end}/*_rotate.ply (gt_files.py)

Frames 00000.. are the start state, then the end state. Run DTArt with ``--num_parts`` = the true
part count (written to rsart_export.json and README.txt).

Import: RUN_DIR is ``runs/<exp>`` or one ``results/step_NNNNNNN`` folder (the newest step is used).
Meshes ``{init,last}_part_{k}.obj`` (k = 0 static, 1..K movable), ``{init,last}_all.obj`` (whole);
motion ``init_motion.json`` (K = 1), ``init_p01..._motion.json`` (identity permutation) or
``init_revolute_motion.json`` (run without GT): per movable slot the part-relative-to-base rigid motion
``rotation``/``translation`` from the start to the end state. The adapter reads that motion as a joint:
revolute (axis = rotation vector, pivot = least-squares point of the axis nearest the part's centroid,
Δ = angle) when it rotates by at least ``min_rotation_deg`` (default 3°), else prismatic (axis = t/|t|,
Δ = |t|). DTArt itself reads the motion under the *true* joint type, which a submission cannot know.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rsart.camera import Camera
from rsart.dataset import RSArtObject
from rsart.errors import RsartError
from rsart.format import read_meta
from rsart.io import atomic_dir, atomic_write_text, read_json
from rsart.twin_io import read_twin

from .base import PROTOCOL_VIEWS, Adapter, ExportReport, ImportReport
from .geometry import MethodFrame, motion_to_joint, rigid
from .gt_files import floats, write_gt
from .images import write_object_depth, write_object_mask, write_segmented_rgb
from .manifest import write_manifest, write_readme
from .paris import _first_mesh
from .states import protocol_runs, require_captured
from .submission_io import STATIC, PartOut, write_entry

_STEP = re.compile(r"^step_(\d+)$")


class DTArtAdapter(Adapter):
    name = "dtart"
    title = "DTArt"
    protocol = "two-state"
    inputs = ("rgb", "depth")
    description = "DTArt (CVPR'24): implicit fields, several movable parts, two RGB-D states, part count given"
    run_layout = "runs/<exp>[/results/step_N]: {init,last}_part_{k}.obj, init_[p<perm>_]motion.json"

    def export(self, object_dir: Path, out_dir: Path, *, frame: str = "z-up", overwrite: bool = False,
               **options: Any) -> ExportReport:
        object_dir, out_dir = Path(object_dir), Path(out_dir)
        fr = MethodFrame.named(frame)
        obj = RSArtObject(object_dir)
        run = protocol_runs(obj.meta, self.protocol, object_dir)[0]
        twin = read_twin(object_dir, obj.meta, visuals=False)
        report = ExportReport(self.name, obj.id, out_dir, self.protocol, {"two-state": {"start": run.start.id,
                                                                                      "end": run.end.id}})
        keyframes: dict[str, Any] = {}
        intr = None
        with atomic_dir(out_dir, overwrite=overwrite) as tmp:
            n = 0
            for t, st in enumerate((run.start, run.end)):
                views = [v for v in require_captured(obj, st.id, self.protocol, ("rgb", "depth", "mask"))
                         if v.split == "train"]
                report.views[st.id] = len(views)
                if len(views) < PROTOCOL_VIEWS:
                    report.notes.append(f"state {st.id} has {len(views)} train views (the paper's protocol "
                                        f"uses {PROTOCOL_VIEWS})")
                for v in views:
                    if intr is None:
                        intr = v.camera.intrinsics
                    elif v.camera.intrinsics != intr:
                        raise RsartError(f"{object_dir}: DTArt takes one cam_K.txt but states "
                                         f"{run.start.id}/{run.end.id} have different intrinsics")
                    fid = f"{n:05d}"
                    n += 1
                    write_segmented_rgb(tmp / "color_segmented" / f"{fid}.png", v)
                    write_object_depth(tmp / "depth_filtered" / f"{fid}.png", v)
                    write_object_mask(tmp / "mask" / f"{fid}.png", v)
                    gl = Camera(v.camera.intrinsics, fr.pose_to_method(v.camera.c2w)).c2w_opengl()
                    keyframes[f"frame_{fid}"] = {"cam_in_ob": floats(gl.reshape(-1)), "time": float(t)}
            atomic_write_text(tmp / "cam_K.txt", "\n".join(" ".join(f"{x:.10g}" for x in row) for row in intr.K) + "\n")
            atomic_write_text(tmp / "init_keyframes.yml", yaml.safe_dump(keyframes, sort_keys=True))
            joints = sorted(obj.meta.joints, key=lambda j: j.child)
            write_gt(tmp / "gt", twin, joints, run.start.values, run.end.values, fr)
            n_parts = len(obj.meta.parts)
            write_manifest(tmp, method=self.name, object_id=obj.id, object_dir=object_dir, protocol=self.protocol,
                           frame=frame, runs={"two-state": {"start": run.start.id, "end": run.end.id}},
                           extra={"num_parts": n_parts, "frames": {"start": report.views[run.start.id],
                                                                   "end": report.views[run.end.id]}})
            write_readme(tmp, "\n".join([
                f"DTArt input for {obj.id} (two-state protocol). In the DigitalTwinArt repository:", "",
                f"ln -s {out_dir.resolve()} data/rsart/{obj.id}",
                f"cd preproc && python gen_correspondence.py --data_path ../data/rsart/{obj.id} "
                f"--output_path ../data/rsart/{obj.id}/correspondence_loftr --top_k=30 && cd ..",
                f"python main.py --data_dir data/rsart/{obj.id} --cfg_dir config/release/ --num_parts {n_parts} "
                f"--save_dir runs/exp_rsart_{obj.id}", "",
                f"then: rsart import --method dtart runs/exp_rsart_{obj.id} --object {obj.id} --data <ROOT> "
                f"--into <SUBMISSION>.json"]))
        return report

    # ------------------------------------------------------------------ import
    def results_dir(self, run_dir: Path) -> Path:
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise RsartError(f"{run_dir}: run folder not found")
        if (run_dir / "init_part_0.obj").is_file():
            return run_dir
        steps = [p for p in run_dir.rglob("step_*") if p.is_dir() and _STEP.match(p.name)
                 and (p / "init_part_0.obj").is_file() and not p.is_symlink()]
        if not steps:
            raise RsartError(f"{run_dir}: no DTArt results (expected {self.run_layout})")
        return max(steps, key=lambda p: (int(_STEP.match(p.name).group(1)), str(p)))

    def read_motions(self, res: Path) -> tuple[list[np.ndarray], str]:
        """Per movable slot k = 1..K, the (4, 4) start->end motion (method frame), and the file read."""
        n = 0
        while (res / f"init_part_{n + 1}.obj").is_file():
            n += 1
        if n == 0:
            raise RsartError(f"{res}: no movable part meshes init_part_1.obj ...")
        names = ["init_revolute_motion.json", "init_prismatic_motion.json", "init_motion.json",
                 f"init_p{''.join(str(i) for i in range(n))}_motion.json"]
        for name in names:
            path = res / name
            if path.is_file():
                d = read_json(path)
                if not isinstance(d, list) or len(d) != n:
                    raise RsartError(f"{path}: expected a list of {n} joints (one per movable part)")
                out = []
                for i, e in enumerate(d):
                    try:
                        R = np.asarray(e["rotation"], np.float64).reshape(3, 3)
                        t = np.asarray(e["translation"], np.float64).reshape(3)
                    except (KeyError, TypeError, ValueError) as err:
                        raise RsartError(f"{path}: entry {i}: needs rotation (3x3) and translation (3) ({err})") from None
                    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
                        raise RsartError(f"{path}: entry {i}: non-finite motion")
                    out.append(rigid(R, t))
                return out, name
        raise RsartError(f"{res}: no motion file ({', '.join(names)})")

    def import_run(self, run_dir: Path, object_dir: Path, submission: Path, *, frame: str = "z-up",
                   method_version: str | None = None, dataset: dict | None = None, min_rotation_deg: float = 3.0,
                   **options: Any) -> ImportReport:
        meta = read_meta(Path(object_dir))
        fr = MethodFrame.named(frame)
        res = self.results_dir(Path(run_dir))
        motions, fname = self.read_motions(res)
        start, end = meta.eval_states["start"], meta.eval_states["end"]
        notes = [f"read {res}/{fname}"]

        def mesh(name: str):
            m = _first_mesh(res, name)
            return fr.mesh_from_method(m) if m is not None else None

        parts = [PartOut(STATIC, {s: m for s, m in ((start, mesh("init_part_0.obj")), (end, mesh("last_part_0.obj")))
                                  if m is not None})]
        for k, M in enumerate(motions, start=1):
            ms = {s: m for s, m in ((start, mesh(f"init_part_{k}.obj")), (end, mesh(f"last_part_{k}.obj"))) if m is not None}
            near = ms[start].vertices.mean(axis=0) if start in ms else np.zeros(3)
            try:
                jt, a, o, d = motion_to_joint(fr.rigid_from_method(M), near, min_rotation_deg)
            except RsartError as e:
                notes.append(f"part_{k}: {e}; left out")
                continue
            notes.append(f"part_{k}: {jt} (rotation {np.degrees(np.linalg.norm(_rotvec(M))):.3f}°, "
                         f"threshold {min_rotation_deg}°) Δ={d:.6g}")
            parts.append(PartOut(f"part_{k}", ms, {"type": jt, "axis": a, "origin": o, "values": {start: 0.0, end: d}}))
        whole = {s: m for s, m in ((start, mesh("init_all.obj")), (end, mesh("last_all.obj"))) if m is not None}
        write_entry(Path(submission), meta.object_id, parts, self.method_record(method_version), dataset,
                    whole=whole or None, notes=notes)
        return ImportReport(self.name, meta.object_id, Path(submission), [p.name for p in parts], notes)


def _rotvec(M: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(M[:3, :3]).as_rotvec()
