"""Run PD²GS over many objects, one task per object, in local processes or on a Ray cluster; resumable.

Used by ``pd2gs run`` and ``benchmarks/pd2gs_suite.py``. A task trains one object (stage ``train``) and
runs one or more discovery configurations ("variants") on the trained field (stage ``discover``). Layout
under the output folder ``out`` (every file written atomically: temp file or folder, then rename)::

    out/runs/<object_id>/config.json, checkpoint.pt, cameras.json   the training run (checkpoint.pt is
                                                                    rewritten every checkpoint_every iters)
    out/runs/<object_id>/metrics.json          written last: the training stage is finished
    out/runs/<object_id>/results/<variant>/    one finished discovery: result.json (+ the meshes, laid out
                                               as in a submission: <object_id>/<state>/<part>.ply)
    out/runs/<object_id>/status.json           the stage the object's task is in (read by the progress bar)
    out/runs/<object_id>/object.json           the last attempt: status, failure reason, timings (s)
    out/runs/<object_id>/log.txt               the object's log, every attempt appended

Resumption: an object whose every variant has a ``done`` result (with the same discovery settings, made
by the same discovery code: :func:`code_id`) is skipped; a finished training run is reused (never retrained); a training run interrupted between
checkpoints continues from its last checkpoint, which restores the optimiser and every random generator
(:meth:`pd2gs.train.Trainer.load_state_dict`), so it reaches the same field as an uninterrupted run.
Discovery always reads the field back from ``checkpoint.pt``, so a fresh and a reused field are the same
bytes. The submission is assembled from the result folders in object order, so an interrupted-and-resumed
run writes the same submission as an uninterrupted one. Bitwise equality needs the same ``threads`` per
task: CPU reductions in torch and numba split work by thread, so another thread count gives other float
rounding.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import logging
import math
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

from rsart.errors import RsartError
from rsart.io import atomic_dir, dumps_json, read_json, write_json

log = logging.getLogger(__name__)

BACKENDS = ("process", "ray")
MAX_ATTEMPTS = 3  # a task whose worker dies this often is reported failed


@dataclass(frozen=True)
class ObjectTask:
    """Everything one worker needs for one object (plain data: it is pickled to the worker).

    ``train``: the :class:`~pd2gs.train.TrainConfig`; ``variants``: variant name -> a
    :class:`~pd2gs.discovery.config.DiscoveryConfig` (empty: train only; ``background`` None = the trained
    field's); ``threads``: CPU threads the task may use (torch intra-op, numba, OpenMP/MKL).
    """

    data: str
    object_id: str
    run_dir: str
    train: Any
    variants: dict[str, Any]
    threads: int = 1


@dataclass
class Outcome:
    """What became of one object: ``status`` done | failed | skipped; ``reason`` for failed ones; per-stage
    wall ``timings`` in seconds (``train_s`` is the training run's own time, also for a reused run)."""

    object_id: str
    status: str
    reason: str | None = None
    timings: dict[str, float] = field(default_factory=dict)


# ----------------------------------------------------------------------------- threads
def set_threads(n: int) -> None:
    """Cap this process's CPU threads to ``n``: OpenMP/MKL (env, for libraries loaded later), torch, numba."""
    n = max(1, int(n))
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[var] = str(n)
    import torch

    torch.set_num_threads(n)
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:  # only settable before the first parallel op (a reused Ray worker)
        pass
    try:
        import numba

        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    except ImportError:  # pragma: no cover - numba is a core dependency
        pass


def default_threads(workers: int) -> int:
    """Threads per task so that ``workers`` tasks fill this machine's cores without oversubscribing them."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))


# ----------------------------------------------------------------------------- state on disk
def _result_dir(run_dir: Path, variant: str) -> Path:
    return run_dir / "results" / variant


def _norm(obj: Any) -> Any:
    """JSON round trip (tuples -> lists, numpy -> python): how a config compares with its stored copy."""
    import json

    return json.loads(dumps_json(obj))


@functools.lru_cache(maxsize=1)
def code_id() -> str:
    """SHA-256 (first 16 hex digits) of the source of the ``pd2gs`` package (every ``*.py`` under it, by
    relative path and bytes): a stored discovery is reused only when the code that made it is the code that
    would remake it. (Keyed by settings alone, a benchmark once rescored results made before a change to
    model selection beside rows made after it.) Training runs are not keyed by it: they are reused
    whatever changed, as they cost minutes per object."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def variant_name(discovery) -> str:
    """The result folder name of a discovery configuration: ``default`` for the default settings, else
    ``settings-<10 hex digits>`` from its settings, so a run with other settings (``pd2gs run --ownership
    staged`` into an ``--out`` that holds a default run) writes beside the finished results instead of
    replacing them. A ``background`` of None (the trained field's) and the field's own background name the
    same folder, as :func:`finished_result` matches them. ``discovery``: a DiscoveryConfig."""
    want = _norm(dataclasses.asdict(discovery))
    base = _norm(dataclasses.asdict(type(discovery)()))
    want.pop("background", None)
    base.pop("background", None)
    if want == base:
        return "default"
    return "settings-" + hashlib.sha256(dumps_json(want).encode()).hexdigest()[:10]


def finished_result(run_dir: Path, variant: str, discovery=None) -> dict | None:
    """The stored ``done`` result of ``variant`` (with these discovery settings, if given, and made by this
    :func:`code_id`), else None.

    A stored result's settings include the background taken from the trained field; ``discovery`` with
    ``background`` None matches any background. ``discovery``: a DiscoveryConfig.
    """
    p = _result_dir(run_dir, variant) / "result.json"
    if not p.is_file():
        return None
    try:
        res = read_json(p)
    except RsartError:
        return None
    if res.get("status") != "done":
        return None
    if discovery is not None:
        want, have = _norm(dataclasses.asdict(discovery)), dict(res.get("discovery", {}))
        if want.get("background") is None:
            have["background"] = None
        if want != have or res.get("code") != code_id():
            return None
    return res


def object_finished(task: ObjectTask) -> bool:
    """True when every variant of ``task`` has a done result and (train-only) the training is finished."""
    run = Path(task.run_dir)
    if not task.variants:
        return (run / "metrics.json").is_file() and (run / "checkpoint.pt").is_file()
    return all(finished_result(run, v, d) is not None for v, d in task.variants.items())


def _status(run: Path, stage: str) -> None:
    write_json(run / "status.json", {"stage": stage, "pid": os.getpid(), "host": socket.gethostname(),
                                     "since": time.time()})


def read_stage(run_dir: str | Path) -> str | None:
    """The stage an object's task last reported (``status.json``), or None."""
    try:
        return read_json(Path(run_dir) / "status.json").get("stage")
    except (RsartError, OSError, AttributeError):
        return None


# ----------------------------------------------------------------------------- one object (the worker)
_TRAIN_KEYS_IGNORED = {"object_dir", "states", "background", "threads"}


def _check_reusable(run: Path, want) -> None:
    """Refuse a finished training run in ``run`` trained with other settings than ``want`` (TrainConfig)."""
    from .train import TrainConfig

    have = dataclasses.asdict(TrainConfig.from_json(read_json(run / "config.json")))
    want_d = dataclasses.asdict(want)
    diff = [k for k in want_d if k not in _TRAIN_KEYS_IGNORED and _norm(want_d[k]) != _norm(have.get(k))
            and not (k == "background" and want_d[k] is None)]
    if want.states and list(want.states) != list(have["states"]):
        diff.append("states")
    if diff:
        k = diff[0]
        raise RsartError(f"{run}: holds a training run with other settings ({k}: {have.get(k)!r}, asked "
                         f"{want_d.get(k)!r}); use another output folder")


def _train_stage(task: ObjectTask, obj, run: Path, timings: dict) -> None:
    from .train import train_object

    cfg = dataclasses.replace(task.train, threads=task.threads)
    if (run / "metrics.json").is_file() and (run / "checkpoint.pt").is_file():
        _check_reusable(run, cfg)
        log.info("training: reusing the finished run in %s", run)
    else:
        _status(run, "train")
        log.info("training: %d iterations, %d threads%s", cfg.iters, cfg.threads,
                 " (resuming from checkpoint.pt)" if (run / "checkpoint.pt").is_file() else "")
        train_object(obj.path, run, cfg, progress=False)
    timings["train_s"] = float(read_json(run / "metrics.json").get("seconds", 0.0))


def _plain(obj: Any) -> Any:
    """Diagnostics as JSON can hold them: numpy values as Python ones, non-finite numbers as None, keys as str."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _plain(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _discover_stage(task: ObjectTask, obj, run: Path, timings: dict) -> list[str]:
    """Run every unfinished variant; -> the reasons of the variants that failed."""
    from .discovery.pipeline import discover_safe
    from .discovery.submission import ObjectFailure, object_entry
    from .train import TrainedModel
    from .train import load_field

    model = None
    failed = []
    for name, cfg in task.variants.items():
        if finished_result(run, name, cfg) is not None:
            log.info("discovery [%s]: reusing the finished result", name)
            timings[f"discover_s[{name}]"] = float(read_json(_result_dir(run, name) / "result.json")["seconds"])
            continue
        _status(run, f"discover:{name}" if len(task.variants) > 1 else "discover")
        if model is None:  # always the stored field: a fresh and a reused run give the same bytes
            tcfg, fld = load_field(run)
            model = TrainedModel(fld, tcfg.states, tcfg.background)
        if cfg.background is None:
            cfg = dataclasses.replace(cfg, background=model.background)
        t0 = time.perf_counter()
        res = discover_safe(model, obj, cfg)
        secs = time.perf_counter() - t0
        timings[f"discover_s[{name}]"] = secs
        with atomic_dir(_result_dir(run, name), overwrite=True) as tmp:
            doc: dict[str, Any] = {"object_id": task.object_id, "variant": name, "discovery": _norm(
                dataclasses.asdict(cfg)), "code": code_id(), "seconds": secs}
            if isinstance(res, ObjectFailure):
                doc.update(status="failed", reason=str(res))
                failed.append(f"{name}: {res}" if len(task.variants) > 1 else str(res))
            else:
                doc.update(status="done", entry=object_entry(res, tmp), diagnostics=_plain(res.diagnostics))
            write_json(tmp / "result.json", doc)
        log.info("discovery [%s]: %s in %.1f s", name, doc["status"], secs)
    return failed


def run_object(task: ObjectTask) -> Outcome:
    """Train and discover one object (in a worker process). Never raises for a failing object: the reason is
    in the Outcome, ``object.json`` and ``log.txt``."""
    set_threads(task.threads)
    from .render.kernel_cache import warm_in_subprocess

    warm_in_subprocess()  # every task loads the same compiled kernels (pd2gs.render.kernel_cache)
    import rsart

    run = Path(task.run_dir)
    run.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(run / "log.txt")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    old_level = root.level
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    try:
        log.info("%s: attempt on %s (pid %d), %d threads", task.object_id, socket.gethostname(), os.getpid(),
                 task.threads)
        _status(run, "load")
        obj = rsart.load(task.data)
        obj = obj if isinstance(obj, rsart.RSArtObject) else obj[task.object_id]
        _train_stage(task, obj, run, timings)
        failed = _discover_stage(task, obj, run, timings)
        out = Outcome(task.object_id, "failed" if failed else "done", "; ".join(failed) or None, timings)
    except Exception as e:  # a failed object is reported, never a crashed run
        log.error("%s: %s: %s\n%s", task.object_id, type(e).__name__, e, traceback.format_exc())
        out = Outcome(task.object_id, "failed", f"{type(e).__name__}: {e}", timings)
    finally:
        root.removeHandler(handler)
        root.setLevel(old_level)
        handler.close()
    out.timings["total_s"] = time.perf_counter() - t0
    _status(run, out.status)
    write_json(run / "object.json", dataclasses.asdict(out))
    return out


# ----------------------------------------------------------------------------- executors
def _ignore_sigint() -> None:
    """Worker processes leave Ctrl-C to the driver, which stops them (no traceback from every worker)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _process_pool(tasks: list[ObjectTask], workers: int) -> Iterator[tuple[ObjectTask, Any] | None]:
    """Run tasks in ``workers`` spawned processes; yield (task, Outcome or exception) as each ends, and None
    about once a second. A pool broken by a dead worker is restarted and the unfinished tasks resubmitted
    (each at most MAX_ATTEMPTS times)."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    attempts = {t.object_id: 0 for t in tasks}
    queue = list(tasks)
    while queue:
        # spawn, not fork: a parent that ran torch's OpenMP aborts forked children
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_ignore_sigint)
        try:
            running: dict[Any, ObjectTask] = {}
            retry: list[ObjectTask] = []
            broken = False
            while running or (queue and not broken):
                while queue and not broken and len(running) < workers:  # only running tasks pay an attempt
                    t = queue.pop(0)
                    attempts[t.object_id] += 1
                    running[pool.submit(run_object, t)] = t
                done, _ = wait(running, timeout=1.0, return_when=FIRST_COMPLETED)
                if not done:
                    yield None  # a tick: the caller refreshes the progress bar
                for f in done:
                    t = running.pop(f)
                    try:
                        res: Any = f.result()
                    except BrokenProcessPool:  # a worker died: every task of this pool ends here
                        broken = True
                        if attempts[t.object_id] < MAX_ATTEMPTS:
                            log.warning("%s: worker process died; retrying", t.object_id)
                            retry.append(t)
                            continue
                        res = RuntimeError(f"its worker process died {attempts[t.object_id]} times")
                    except Exception as e:  # pragma: no cover - run_object catches object failures
                        res = e
                    yield t, res
            queue = retry + queue
        finally:
            procs = list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for p in procs:  # Ctrl-C or an error in the caller: stop the running tasks too
                if p.is_alive():
                    p.terminate()


def import_ray():
    """The ``ray`` module, or a one-line :class:`~rsart.extras.MissingExtra` saying how to install it."""
    from rsart.extras import MissingExtra

    try:
        import ray
    except ImportError:
        raise MissingExtra("ray", "ray", "--backend ray") from None
    return ray


def _ray(tasks: list[ObjectTask], workers: int | None, address: str | None,
         threads: int) -> Iterator[tuple[ObjectTask, Any] | None]:
    """Run tasks as Ray tasks (``threads`` CPUs each, at most ``workers`` at a time; a local Ray with
    workers x threads CPUs unless ``address``). Ray reruns a task whose worker or node died (MAX_ATTEMPTS
    in all); the rerun resumes from the stages on disk, so the output folder must be on storage every node
    sees. Yields like :func:`_process_pool`."""
    ray = import_ray()
    started = False
    if not ray.is_initialized():
        env = {"env_vars": {v: str(threads) for v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                                      "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")}}
        kw: dict[str, Any] = {"address": address} if address else {"num_cpus": (workers or 1) * threads}
        ray.init(ignore_reinit_error=True, log_to_driver=False, include_dashboard=False, runtime_env=env,
                 **kw)
        started = True
    try:
        if workers is None:
            workers = max(1, int(ray.cluster_resources().get("CPU", 1)) // threads)
        remote = ray.remote(num_cpus=threads, max_retries=MAX_ATTEMPTS - 1)(run_object)
        queue = list(tasks)
        running: dict[Any, ObjectTask] = {}
        while queue or running:
            while queue and len(running) < workers:
                t = queue.pop(0)
                running[remote.remote(t)] = t
            ready, _ = ray.wait(list(running), num_returns=1, timeout=1.0)
            if not ready:
                yield None
            for ref in ready:
                t = running.pop(ref)
                try:
                    yield t, ray.get(ref)
                except Exception as e:  # WorkerCrashedError / NodeDiedError after the retries
                    yield t, RuntimeError(f"its Ray worker died {MAX_ATTEMPTS} times ({type(e).__name__})")
    finally:
        if started:
            ray.shutdown()


class _Progress:
    """One bar over objects; the postfix shows each running object's stage (from its status.json)."""

    def __init__(self, tasks: list[ObjectTask], enabled: bool):
        from tqdm import tqdm

        self.running = {t.object_id: t.run_dir for t in tasks}
        self.bar = tqdm(total=len(tasks), desc="objects", unit="obj", disable=not enabled, dynamic_ncols=True)

    def refresh(self) -> None:
        stages = [(oid, read_stage(rd)) for oid, rd in self.running.items()]
        self.bar.set_postfix_str(" | ".join(f"{oid}: {s}" for oid, s in stages if s), refresh=True)

    def finished(self, out: Outcome) -> None:
        self.running.pop(out.object_id, None)
        msg = "done" if out.status == "done" else f"failed: {out.reason}"
        self.bar.write(f"[pd2gs] {out.object_id}: {msg} ({out.timings.get('total_s', 0):.0f} s)")
        self.bar.update(1)
        self.refresh()

    def close(self) -> None:
        self.bar.close()


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """While the driver waits on its workers, SIGTERM (``kill``, a scheduler's stop) is handled as Ctrl-C:
    the executors' ``finally`` stops the workers instead of leaving them orphaned, still writing into the
    run folders (measured: a benchmark killed with ``pkill`` left both of its workers running). Only the
    main thread can set a handler; elsewhere nothing changes."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    old = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def execute(tasks: list[ObjectTask], backend: str = "process", workers: int | None = None,
            address: str | None = None, progress: bool = True) -> dict[str, Outcome]:
    """Run every unfinished task; -> object id -> Outcome (``skipped`` for objects finished earlier).

    ``backend`` "process" (``workers`` local processes; default 1) or "ray" (``address`` of a running
    cluster, else a local Ray). Each task's ``threads`` is set in its worker before any work.
    Ctrl-C stops the workers; what finished stays on disk and a rerun resumes from it.
    """
    if backend not in BACKENDS:
        raise RsartError(f"backend {backend!r} is not one of {', '.join(BACKENDS)}")
    if backend == "ray":
        import_ray()
    if workers is not None and workers < 1:
        raise RsartError(f"workers must be at least 1, got {workers}")
    outcomes: dict[str, Outcome] = {}
    todo = []
    for t in tasks:
        if object_finished(t):
            outcomes[t.object_id] = Outcome(t.object_id, "skipped", timings=_stored_timings(t))
        else:
            Path(t.run_dir, "status.json").unlink(missing_ok=True)  # a stale stage from an earlier run
            todo.append(t)
    if not todo:
        return outcomes
    threads = todo[0].threads
    events = (_ray(todo, workers, address, threads) if backend == "ray"
              else _process_pool(todo, min(workers or 1, len(todo))))
    bar = _Progress(todo, progress)
    try:
        with _sigterm_as_interrupt():
            for ev in events:
                if ev is None:
                    bar.refresh()
                    continue
                t, res = ev
                out = res if isinstance(res, Outcome) else Outcome(t.object_id, "failed", str(res))
                if not isinstance(res, Outcome):
                    write_json(Path(t.run_dir) / "object.json", dataclasses.asdict(out))
                outcomes[t.object_id] = out
                bar.finished(out)
    finally:
        events.close()
        bar.close()
    return outcomes


def _stored_timings(task: ObjectTask) -> dict[str, float]:
    """The timings of an object finished in an earlier run (training run + stored discovery results)."""
    run = Path(task.run_dir)
    tm = {"train_s": float(read_json(run / "metrics.json").get("seconds", 0.0))}
    for v in task.variants:
        tm[f"discover_s[{v}]"] = float(read_json(_result_dir(run, v) / "result.json").get("seconds", 0.0))
    return tm


# ----------------------------------------------------------------------------- submission + summary
def assemble(tasks: list[ObjectTask], variant: str, outcomes: dict[str, Outcome], out_dir: str | os.PathLike,
             method_block: dict, dataset_block: dict) -> Path:
    """Write the submission of ``variant`` from the objects' stored results, in task order (atomic folder).

    An object without a done result is ``null`` with its reason in failures.json."""
    from .discovery.submission import write_submission_entries

    entries: dict[str, dict | None] = {}
    reasons: dict[str, str] = {}
    mesh_dirs: dict[str, Path] = {}
    for t in tasks:
        rdir = _result_dir(Path(t.run_dir), variant)
        res = read_json(rdir / "result.json") if (rdir / "result.json").is_file() else None
        if res is not None and res.get("status") == "done":
            entries[t.object_id] = res["entry"]
            mesh_dirs[t.object_id] = rdir
        else:
            entries[t.object_id] = None
            o = outcomes.get(t.object_id)
            reasons[t.object_id] = (res or {}).get("reason") or (o.reason if o and o.reason else "no result")
    return write_submission_entries(entries, reasons, mesh_dirs, out_dir, method_block, dataset_block)


def summarize(outcomes: dict[str, Outcome], path: str | os.PathLike | None = None,
              say: Callable[[str], None] = print) -> dict:
    """Print (and write to ``path``) which objects are done, failed (with reasons) and skipped."""
    groups: dict[str, list[Outcome]] = {"done": [], "failed": [], "skipped": []}
    for o in outcomes.values():
        groups[o.status].append(o)
    doc = {"done": [o.object_id for o in groups["done"]],
           "failed": {o.object_id: o.reason for o in groups["failed"]},
           "skipped": [o.object_id for o in groups["skipped"]],
           "timings": {o.object_id: o.timings for o in outcomes.values()}}
    if path is not None:
        write_json(path, doc)
    say(f"[pd2gs] done {len(groups['done'])}, failed {len(groups['failed'])}, skipped {len(groups['skipped'])} "
        f"(finished in an earlier run)")
    for key in ("done", "skipped"):
        if groups[key]:
            say(f"  {key}: {', '.join(o.object_id for o in groups[key])}")
    for o in groups["failed"]:
        say(f"  failed: {o.object_id}: {o.reason}")
    return doc
