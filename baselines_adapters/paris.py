"""PARIS (Liu et al., ICCV 2023) and ArticulatedGS (Guo et al., CVPR 2025): single-joint, two-state,
RGB only, the same input layout.

Export (single-joint protocol: one run per movable joint, that joint at its min and max, the others at
the start state), per joint ``<out>/<joint>/``::

    load/{start,end}/{train,val,test}/NNNN.png   RGBA, alpha 255 on the object (val = the test views)
    load/{start,end}/camera_{train,val,test}.json  {"K": 3x3, "NNNN": 4x4 camera-to-world, OpenGL axes}
    gt/trans.json, gt/{start,end}/*_rotate.ply     ground truth (gt_files.py), z-up method frame

``K`` is written with the principal point in PARIS's pixel convention (pixel centres at i + 0.5, so
rsart's cx + 0.5); PARIS itself uses only K[0][0] and puts the principal point at the image centre.

Import: ``RUN_DIR/<joint>/...`` holds each joint's run (searched recursively). PARIS: the newest
``it<N>_{test,val}_motion.json`` — ``{type: rotate, axis_o, axis_d, rot_angle (degrees, start->end),
R}`` or ``{type: translate, axis_o, axis_d, dist}`` — with ``it<N>_static_*.ply`` and
``it<N>_dyn_t0_*.ply`` (the moving part at the start state). ArticulatedGS: ``motion.json`` —
``{type: revolute, axis (not normalised), pivot, theta (radians)}`` or ``{type: prismatic, axis, dist}``;
it exports no meshes, so meshes are read only if the run folder also holds ``static.ply`` and
``dynamic.ply`` (the moving part at the start state) that the user extracted. The runs are merged into
one submission entry (merge.py).
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from rsart.dataset import RSArtObject
from rsart.errors import RsartError
from rsart.evaluation.submission import MeshError, load_mesh
from rsart.format import read_meta
from rsart.io import atomic_dir, read_json, write_json
from rsart.twin_io import read_twin

from .base import PROTOCOL_VIEWS, Adapter, ExportReport, ImportReport
from .geometry import MethodFrame, unit
from .gt_files import floats, write_gt
from .images import write_rgba
from .manifest import write_manifest, write_readme
from .merge import JointRun, merge_runs
from .states import Run, protocol_runs, require_captured
from .submission_io import write_entry

_PARIS_MOTION = re.compile(r"^it(\d+)_(test|val)_motion\.json$")


def paris_K(intr) -> list[list[float]]:
    """3x3 K in PARIS's pixel convention (principal point + 0.5)."""
    return [[float(intr.fx), 0.0, float(intr.cx) + 0.5], [0.0, float(intr.fy), float(intr.cy) + 0.5], [0.0, 0.0, 1.0]]


def write_paris_state(obj: RSArtObject, state_id: str, folder: Path, frame: MethodFrame, protocol: str,
                      splits: dict[str, str] | None = None) -> tuple[int, list[str], Any]:
    """Write one state as ``folder/{train,val,test}/NNNN.png`` + ``folder/camera_{split}.json``.

    ``splits`` maps PARIS split -> rsart split (default train->train, val->test, test->test). Returns
    (train views written, notes, intrinsics).
    """
    views = require_captured(obj, state_id, protocol, ("rgb", "mask"))
    intr = views[0].camera.intrinsics
    notes = []
    if abs(intr.fx - intr.fy) > 1e-6 * intr.fx:
        notes.append(f"{state_id}: fx {intr.fx:g} != fy {intr.fy:g}; PARIS uses fx for both")
    if abs(intr.cx + 0.5 - intr.width / 2) > 0.5 or abs(intr.cy + 0.5 - intr.height / 2) > 0.5:
        notes.append(f"{state_id}: principal point is off the image centre; PARIS assumes it at the centre")
    splits = splits or {"train": "train", "val": "test", "test": "test"}
    n_train = 0
    for psplit, rsplit in splits.items():
        cams: dict[str, Any] = {"K": paris_K(intr)}
        for i, v in enumerate(x for x in views if x.split == rsplit):
            name = f"{i:04d}"
            write_rgba(folder / psplit / f"{name}.png", v)
            cams[name] = floats(_gl_pose(v.camera, frame))
            n_train += psplit == "train"
        write_json(folder / f"camera_{psplit}.json", cams)
    return n_train, notes, intr


def _gl_pose(camera, frame: MethodFrame) -> np.ndarray:
    """OpenGL camera-to-world in the method frame (rsart.camera does the axis flip)."""
    from rsart.camera import Camera

    return Camera(camera.intrinsics, frame.pose_to_method(camera.c2w)).c2w_opengl()


class ParisAdapter(Adapter):
    name = "paris"
    title = "PARIS"
    protocol = "single-joint"
    inputs = ("rgb",)
    description = "PARIS (ICCV'23): NeRF, one movable part, two states; run once per joint and merged"
    run_layout = "RUN_DIR/<joint name>/**/it<N>_test_motion.json + it<N>_static_*.ply + it<N>_dyn_t0_*.ply"

    # ------------------------------------------------------------------ export
    def export(self, object_dir: Path, out_dir: Path, *, frame: str = "z-up", overwrite: bool = False,
               **options: Any) -> ExportReport:
        object_dir, out_dir = Path(object_dir), Path(out_dir)
        fr = MethodFrame.named(frame)
        obj = RSArtObject(object_dir)
        runs = protocol_runs(obj.meta, self.protocol, object_dir)
        twin = read_twin(object_dir, obj.meta, visuals=False)
        report = ExportReport(self.name, obj.id, out_dir, self.protocol, {})
        man_runs = {}
        with atomic_dir(out_dir, overwrite=overwrite) as tmp:
            for run in runs:
                rdir = tmp / run.name
                for key, st in (("start", run.start), ("end", run.end)):
                    n, notes, _ = write_paris_state(obj, st.id, rdir / "load" / key, fr, self.protocol)
                    report.views[st.id] = n
                    report.notes += [n_ for n_ in notes if n_ not in report.notes]
                    if n < PROTOCOL_VIEWS:
                        msg = f"state {st.id} has {n} train views (the paper's protocol uses {PROTOCOL_VIEWS})"
                        if msg not in report.notes:
                            report.notes.append(msg)
                write_gt(rdir / "gt", twin, [run.joint], run.start.values, run.end.values, fr)
                report.runs[run.name] = {"start": run.start.id, "end": run.end.id}
                man_runs[run.name] = {"start": run.start.id, "end": run.end.id, "joint": run.joint.name,
                                      "type": run.joint.type, "folder": run.name}
            write_manifest(tmp, method=self.name, object_id=obj.id, object_dir=object_dir, protocol=self.protocol,
                           frame=frame, runs=man_runs)
            write_readme(tmp, self.readme(obj.id, runs, out_dir, obj))
        return report

    def readme(self, oid: str, runs: list[Run], out_dir: Path, obj: RSArtObject) -> str:
        v = obj.states[runs[0].start.id].views[0].camera.intrinsics
        lines = [f"PARIS input for {oid} (single-joint protocol: one run per joint). In the PARIS repository:", ""]
        for r in runs:
            cfg = "revolute" if r.joint.type == "revolute" else "prismatic"
            lines.append(f"python launch.py --config configs/{cfg}.yaml --gpu 0 --train "
                         f"source=rsart/{oid}/{r.name} dataset.root_dir={out_dir.resolve()}/{r.name}/load "
                         f"model.motion_gt_path={out_dir.resolve()}/{r.name}/gt/trans.json "
                         f"\"dataset.img_wh=[{v.width},{v.height}]\"")
        lines += ["", f"then: rsart import --method paris exp/rsart/{oid} --object {oid} --data <ROOT> --into <SUBMISSION>.json"]
        return "\n".join(lines)

    # ------------------------------------------------------------------ import
    def find_runs(self, run_dir: Path, joints: list[str]) -> dict[str, Path]:
        """Joint name -> the motion file of its run (newest iteration, test before val)."""
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise RsartError(f"{run_dir}: run folder not found")
        out = {}
        for jn in joints:
            base = run_dir / jn
            if not base.is_dir() and len(joints) == 1:
                base = run_dir
            if base.is_dir():
                f = self._motion_file(base)
                if f is not None:
                    out[jn] = f
        if not out:
            raise RsartError(f"{run_dir}: no run found for any joint (expected {self.run_layout}; joints: {joints})")
        return out

    def _motion_file(self, folder: Path) -> Path | None:
        best = None
        for p in folder.rglob("*_motion.json"):
            m = _PARIS_MOTION.match(p.name)
            if m and not p.is_symlink():
                key = (int(m.group(1)), m.group(2) == "test", str(p))
                if best is None or key > best[0]:
                    best = (key, p)
        return best[1] if best else None

    def read_motion(self, path: Path) -> tuple[str, np.ndarray, np.ndarray, float]:
        """(type, axis, origin, Δ) in the method frame from a PARIS motion.json (degrees -> radians)."""
        d = read_json(path)
        if not isinstance(d, dict) or d.get("type") not in ("rotate", "translate"):
            raise RsartError(f"{path}: expected a PARIS motion file with type 'rotate' or 'translate'")
        try:
            o = np.asarray(d["axis_o"], np.float64).reshape(3)
            a = unit(np.asarray(d["axis_d"], np.float64).reshape(3), f"{path}: axis_d")
            if d["type"] == "rotate":
                return "revolute", a, o, math.radians(_scalar(d["rot_angle"]))
            return "prismatic", a, o, _scalar(d["dist"])
        except KeyError as e:
            raise RsartError(f"{path}: missing key {e.args[0]!r}") from None
        except (TypeError, ValueError) as e:
            raise RsartError(f"{path}: malformed motion ({e})") from None

    def read_meshes(self, motion: Path) -> tuple[Any, Any]:
        m = _PARIS_MOTION.match(motion.name)
        it = m.group(1) if m else None
        return (_first_mesh(motion.parent, f"it{it}_static_*.ply"), _first_mesh(motion.parent, f"it{it}_dyn_t0_*.ply"))

    def import_run(self, run_dir: Path, object_dir: Path, submission: Path, *, frame: str = "z-up",
                   method_version: str | None = None, dataset: dict | None = None, merge_eps: float = 0.01,
                   **options: Any) -> ImportReport:
        object_dir = Path(object_dir)
        meta = read_meta(object_dir)
        fr = MethodFrame.named(frame)
        files = self.find_runs(Path(run_dir), [j.name for j in meta.joints])
        runs = {}
        for jn, f in files.items():
            jtype, a, o, delta = self.read_motion(f)
            true_type = meta.joint(jn).type
            static, dyn = self.read_meshes(f)
            runs[jn] = JointRun(jtype, fr.dirs_from_method(a), fr.points_from_method(o), delta,
                                fr.mesh_from_method(static) if static is not None else None,
                                fr.mesh_from_method(dyn) if dyn is not None else None, str(f))
            if jtype != true_type:
                runs[jn].source += f" (run as {jtype}, true joint is {true_type})"
        parts, notes = merge_runs(meta, runs, merge_eps)
        write_entry(Path(submission), meta.object_id, parts, self.method_record(method_version), dataset,
                    notes=notes)
        return ImportReport(self.name, meta.object_id, Path(submission), [p.name for p in parts], notes)


def _scalar(x: Any) -> float:
    v = np.asarray(x, np.float64).reshape(-1)
    if v.size != 1 or not np.isfinite(v[0]):
        raise ValueError(f"expected one finite number, got {x!r}")
    return float(v[0])


def _first_mesh(folder: Path, pattern: str):
    found = sorted(p for p in folder.glob(pattern) if p.is_file() and not p.is_symlink())
    if not found:
        return None
    try:
        return load_mesh(found[0])
    except MeshError as e:
        raise RsartError(f"{found[0]}: {e}") from None


class ArticulatedGSAdapter(ParisAdapter):
    name = "articulatedgs"
    title = "ArticulatedGS"
    description = "ArticulatedGS (CVPR'25): 3DGS, one movable part, PARIS layout; joints only (no meshes published)"
    run_layout = "RUN_DIR/<joint name>/**/motion.json [+ static.ply, dynamic.ply you extracted]"

    def readme(self, oid: str, runs: list[Run], out_dir: Path, obj: RSArtObject) -> str:
        lines = [f"ArticulatedGS input for {oid} (PARIS layout; single-joint protocol: one run per joint).",
                 "In the ArticulatedGS repository, per joint (paths as its README's data/<category>/<id>):", ""]
        for r in runs:
            lines.append(f"ln -s {out_dir.resolve()}/{r.name}/load data/rsart/{oid}_{r.name}   "
                         f"# then train on data/rsart/{oid}_{r.name}; keep its output folder as "
                         f"<RUN_DIR>/{r.name}/")
        lines += ["", f"then: rsart import --method articulatedgs <RUN_DIR> --object {oid} --data <ROOT> --into <SUBMISSION>.json"]
        return "\n".join(lines)

    def _motion_file(self, folder: Path) -> Path | None:
        found = sorted((p for p in folder.rglob("motion.json") if p.is_file() and not p.is_symlink()),
                       key=lambda p: (p.stat().st_mtime, str(p)))
        return found[-1] if found else None

    def read_motion(self, path: Path) -> tuple[str, np.ndarray, np.ndarray, float]:
        """(type, axis, origin, Δ) from ArticulatedGS motion.json: axis normalised here; theta radians."""
        d = read_json(path)
        if not isinstance(d, dict) or d.get("type") not in ("revolute", "prismatic"):
            raise RsartError(f"{path}: expected an ArticulatedGS motion file with type 'revolute' or 'prismatic'")
        try:
            raw = np.asarray(d["axis"], np.float64).reshape(3)
            a = unit(raw, f"{path}: axis")
            if d["type"] == "revolute":
                return "revolute", a, np.asarray(d["pivot"], np.float64).reshape(3), _scalar(d["theta"])
            # the travel is along the normalised axis
            return "prismatic", a, np.zeros(3), _scalar(d["dist"])
        except KeyError as e:
            raise RsartError(f"{path}: missing key {e.args[0]!r}") from None
        except (TypeError, ValueError) as e:
            raise RsartError(f"{path}: malformed motion ({e})") from None

    def read_meshes(self, motion: Path) -> tuple[Any, Any]:
        return _first_mesh(motion.parent, "static.ply"), _first_mesh(motion.parent, "dynamic.ply")
