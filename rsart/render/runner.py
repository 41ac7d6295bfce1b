"""Render object folders: plan views, write cameras.json, render in worker processes, resume.

Layout written under a dataset root ``out`` (DESIGN.md §6.1)::

    out/index.json, out/checksums.sha256
    out/<object_id>/meta.json               (+ states the protocol added, e.g. unseen ones)
    out/<object_id>/render.json             the settings of each protocol rendered here (seed, options, ...)
    out/<object_id>/twin/...                copied from the input object folder / written from URDF/USD
    out/<object_id>/states/<sid>/cameras.json
    out/<object_id>/states/<sid>/{rgb,depth,mask}/<view>.png   (+ rgb_clean/, depth_clean/ with --sensor)

Resume: every image is written atomically (temp file + rename), so a view is finished exactly when
all its files exist; a re-run with the same settings renders only unfinished views and, because
every random draw is seeded by (seed, object, state, view), produces the same bytes as an
uninterrupted run. Protocols can share a folder (their states must agree); re-rendering a state
with other cameras or settings is refused unless ``overwrite``.
"""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import RsartError
from ..format import (CamerasFile, DatasetIndex, ObjectMeta, ViewRecord, cameras_to_dict, read_index, read_meta,
                      write_cameras, write_index, write_meta)
from ..io import dumps_json, read_json, write_json
from ..kinematics import Twin
from .frame import RenderOptions
from .paths import PathSpec, circular_path, fit_radius, fixed_test_views, random_views
from .protocols import ProtocolPlan, plan_protocol
from .worker import init_worker, render_task, stable_seed

RENDER_FORMAT = "rsart-render/1"
MANIFEST = "render.json"


@dataclass(frozen=True)
class RenderJob:
    """Everything that determines the rendered bytes (recorded in ``render.json``)."""

    protocol: str = "pd2gs"
    seed: int = 0
    views: int | None = None
    test_views: int | None = None
    train_path: str = "circle"
    options: RenderOptions = RenderOptions()
    path: PathSpec = PathSpec()

    def manifest(self) -> dict:
        return {"format": RENDER_FORMAT, "protocol": self.protocol, "seed": self.seed, "views": self.views,
                "test_views": self.test_views, "train_path": self.train_path,
                "options": self.options.to_dict(), "path": asdict(self.path)}


@dataclass
class ViewTask:
    """One state's views to render in one worker call (``views``: (id, c2w (4, 4)) pairs)."""

    obj_dir: str
    object_id: str
    state_id: str
    values: dict[str, float]
    bounds: np.ndarray
    radius: float
    views: list[tuple[str, np.ndarray]]
    job: RenderJob
    twin: Twin | None = field(default=None, repr=False)


@dataclass
class ObjectPlan:
    """The planned render of one object folder."""

    obj_dir: Path
    meta: ObjectMeta
    protocol: ProtocolPlan
    cameras: dict[str, CamerasFile]
    bounds: np.ndarray
    radius: float


def view_files(state_dir: Path, view_id: str, sensor: bool) -> list[Path]:
    """The files of one finished view."""
    kinds = ["rgb", "depth", "mask"] + (["rgb_clean", "depth_clean"] if sensor else [])
    return [state_dir / k / f"{view_id}.png" for k in kinds]


# ----------------------------------------------------------------------------- planning
def plan_object(obj_dir: Path, twin: Twin, meta: ObjectMeta, job: RenderJob) -> ObjectPlan:
    """States, camera poses and booth placement of ``meta``'s object under ``job`` (deterministic)."""
    proto = plan_protocol(job.protocol, meta, job.views, job.test_views)
    intr = job.options.intrinsics
    bounds = np.array([np.full(3, np.inf), np.full(3, -np.inf)])
    for sp in proto.states:
        b = twin.bounds(sp.state.values)
        bounds = np.array([np.minimum(bounds[0], b[0]), np.maximum(bounds[1], b[1])])
    radius = fit_radius(bounds, intr, job.path.fill)
    target = bounds.mean(axis=0)
    test = fixed_test_views(target, radius, max(sp.n_test for sp in proto.states), job.path)
    cameras = {}
    for sp in proto.states:
        rng = np.random.default_rng(stable_seed(job.seed, meta.object_id, sp.state.id, "path"))
        if job.train_path == "circle":
            train = circular_path(target, radius, sp.n_train, rng, job.path)
        elif job.train_path == "random":
            train = random_views(target, radius, sp.n_train, rng, job.path)
        else:
            raise RsartError(f"train path {job.train_path!r} is not 'circle' or 'random'")
        views = [ViewRecord(f"{i:04d}", c, "train") for i, c in enumerate(train)]
        views += [ViewRecord(f"{sp.n_train + i:04d}", test[i], "test") for i in range(sp.n_test)]
        cameras[sp.state.id] = CamerasFile(intr, job.options.depth_scale, views,
                                           extra={"protocol": job.protocol, "state": sp.state.id,
                                                  "settings": settings_digest(job)})
    return ObjectPlan(obj_dir, meta, proto, cameras, bounds, radius)


def settings_digest(job: RenderJob) -> str:
    """Short SHA-256 of everything that determines a state's images (recorded in its cameras.json)."""
    import hashlib

    return hashlib.sha256(dumps_json(job.manifest()).encode()).hexdigest()[:16]


def write_plan(plan: ObjectPlan, job: RenderJob, overwrite: bool = False) -> None:
    """Write meta.json (with added states), render.json and every cameras.json.

    Several protocols may share an object folder (e.g. pd2gs for training and unseen for testing)
    as long as every state they share was rendered with the same cameras and settings; any state
    whose existing cameras.json differs is a conflict: refused, or with ``overwrite`` re-rendered.
    """
    obj = plan.obj_dir
    manifest = json.loads(dumps_json(job.manifest()))  # as it reads back (tuples -> lists)
    mpath = obj / MANIFEST
    record = read_json(mpath) if mpath.exists() else {}
    if record.get("format") != RENDER_FORMAT or not isinstance(record.get("protocols"), dict):
        record = {"format": RENDER_FORMAT, "protocols": {}}
    wanted = {sid: json.loads(dumps_json(cameras_to_dict(c))) for sid, c in plan.cameras.items()}
    conflicts = [sid for sid in wanted if (obj / "states" / sid / "cameras.json").exists()
                 and read_json(obj / "states" / sid / "cameras.json") != wanted[sid]]
    if conflicts:
        if not overwrite:
            prev = record["protocols"].get(job.protocol)
            why = (f"protocol {job.protocol} differs in "
                   + ", ".join(sorted(k for k in set(prev) | set(manifest) if prev.get(k) != manifest.get(k)))
                   if prev and prev != manifest else "other cameras or settings")
            raise RsartError(f"{obj}: states {', '.join(conflicts)} were already rendered with other settings "
                             f"({why}); use another --out or pass --overwrite")
        for sid in conflicts:
            shutil.rmtree(obj / "states" / sid)
    meta = plan.meta
    if plan.protocol.new_states:
        known = {s.id for s in meta.states}
        meta.states = list(meta.states) + [s for s in plan.protocol.new_states if s.id not in known]
        write_meta(meta, obj / "meta.json")
    for sid, cams in plan.cameras.items():
        sdir = obj / "states" / sid
        sdir.mkdir(parents=True, exist_ok=True)
        for tmp in [*sdir.glob(".*.tmp"), *sdir.glob("*/.*.tmp")]:  # leftovers of a killed run
            tmp.unlink(missing_ok=True)
        if not (sdir / "cameras.json").exists():
            write_cameras(cams, sdir / "cameras.json")
    record["protocols"][job.protocol] = manifest
    write_json(mpath, record)


def pending_tasks(plan: ObjectPlan, twin: Twin, job: RenderJob, chunk: int = 8) -> list[ViewTask]:
    """Unfinished views, grouped by state into chunks of at most ``chunk`` views."""
    tasks = []
    for sp in plan.protocol.states:
        sdir = plan.obj_dir / "states" / sp.state.id
        todo = [(v.id, v.c2w) for v in plan.cameras[sp.state.id].views
                if not all(f.exists() for f in view_files(sdir, v.id, job.options.sensor))]
        for i in range(0, len(todo), chunk):
            tasks.append(ViewTask(str(plan.obj_dir), plan.meta.object_id, sp.state.id, dict(sp.state.values),
                                  plan.bounds, plan.radius, todo[i:i + chunk], job, twin))
    return tasks


def run_tasks(tasks: list[ViewTask], workers: int = 1, backend: str = "process", address: str | None = None,
              progress: bool = True, desc: str = "render") -> int:
    """Run ``tasks`` in this process (workers=1), a process pool, or on Ray; returns views written."""
    from tqdm import tqdm

    total = sum(len(t.views) for t in tasks)
    bar = tqdm(total=total, desc=desc, unit="view", disable=not progress or total == 0)
    done = 0
    try:
        if backend == "ray":
            from .ray_backend import run_on_ray
            for n in run_on_ray(tasks, address=address, workers=workers):
                done += n
                bar.update(n)
        elif workers <= 1 or len(tasks) <= 1:
            init_worker(0)
            for t in tasks:
                n = render_task(t)
                done += n
                bar.update(n)
        else:
            import concurrent.futures as cf
            import multiprocessing as mp

            ctx = mp.get_context("spawn")  # fresh interpreters: no forked GL/open3d state
            with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=init_worker,
                                        initargs=(1,)) as ex:
                futs = [ex.submit(render_task, t) for t in tasks]
                try:
                    for fu in cf.as_completed(futs):
                        n = fu.result()
                        done += n
                        bar.update(n)
                except BaseException:
                    for fu in futs:
                        fu.cancel()
                    raise
    finally:
        bar.close()
    return done


# ----------------------------------------------------------------------------- objects and datasets
def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def render_object_dir(obj_dir: Path, job: RenderJob, workers: int | None = None, backend: str = "process",
                      address: str | None = None, progress: bool = True, overwrite: bool = False,
                      twin: Twin | None = None) -> ObjectPlan:
    """Render the states of an existing object folder in place (meta.json + twin/ already there)."""
    from ..twin_io import read_twin

    obj_dir = Path(obj_dir)
    meta = read_meta(obj_dir)
    twin = twin or read_twin(obj_dir, meta)
    plan = plan_object(obj_dir, twin, meta, job)
    write_plan(plan, job, overwrite=overwrite)
    tasks = pending_tasks(plan, twin, job)
    run_tasks(tasks, workers or default_workers(), backend, address, progress, desc=meta.object_id)
    return plan


def update_index(root: Path, object_ids: list[str], name: str | None = None) -> None:
    """Create or extend ``root/index.json`` with ``object_ids`` (split "all" lists every object)."""
    path = root / "index.json"
    if path.exists():
        idx = read_index(path)
        objs = idx.objects + [o for o in object_ids if o not in idx.objects]
        splits = dict(idx.splits)
        splits["all"] = list(objs)
        idx = DatasetIndex(idx.name, idx.version, objs, splits, idx.format, idx.extra)
    else:
        idx = DatasetIndex(name or root.name or "rsart", "1", list(object_ids), {"all": list(object_ids)})
    write_index(idx, path)


def finish_root(root: Path, object_ids: list[str], name: str | None = None) -> Path:
    """Write index.json and checksums.sha256 of the dataset root; returns the checksum file."""
    from ..verify import write_checksums

    update_index(root, object_ids, name)
    return write_checksums(root)
