"""Scoring workers: take jobs from the queue, score them with rsart's evaluation, ingest the scores.

A worker is a separate process (``python -m leaderboards.worker``, started by ``rsart leaderboard serve``).
It validates the submission exactly as ``rsart-eval`` does (structure, files, then every mesh's content),
scores it with one process, writes ``scores.json`` and ``summary.md`` to ``<work>/jobs/<id>/eval`` and ingests them
(idempotently, so a job re-run after a crash never duplicates an entry).

Leases (:mod:`leaderboards.jobs`): while scoring, a thread refreshes the job's heartbeat every
``HEARTBEAT_S`` and checks that the parent (the server) is alive; when the parent is gone the worker stops
at once, mid-job, without finishing it (the job is re-queued when its lease expires, so a restarted server
never has two workers scoring it). Between jobs it exits when its parent dies, and while idle it re-queues
jobs whose lease expired (their worker died).
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

from .jobs import HEARTBEAT_S, LEASE_S, claim, finish, heartbeat, recover
from .schema import open_engine
from .store import add_scores

log = logging.getLogger("leaderboards.worker")


@dataclass(frozen=True)
class ScoringSettings:
    """rsart-eval settings the server scores with (recorded in every scores.json's config hash)."""

    chamfer_samples: int = 10000
    chamfer_seeds: tuple[int, ...] = (0, 1, 2)
    states: str = "start,end"
    max_mesh_mb: float = 200.0

    def argv(self) -> list[str]:
        return ["--chamfer-samples", str(self.chamfer_samples),
                "--chamfer-seeds", ",".join(map(str, self.chamfer_seeds)), "--states", self.states,
                "--max-mesh-mb", str(self.max_mesh_mb)]


class JobError(Exception):
    """A submission problem to report to the team (not a crash)."""


def _problems_text(problems) -> str:
    lines = [f"invalid submission, {len(problems)} problem(s):"] + [f"  - {p}" for p in problems[:50]]
    if len(problems) > 50:
        lines.append(f"  … {len(problems) - 50} more")
    return "\n".join(lines)


def score_job(job: dict, data_root: Path, work: Path, settings: ScoringSettings, engine) -> int:
    """Validate, score and ingest one job → submission id (JobError for a bad submission)."""
    from rsart.evaluation.cli import check_mesh_content
    from rsart.evaluation.ground_truth import load_ground_truth, resolve_states
    from rsart.evaluation.report import build_scores, summary_markdown
    from rsart.io import atomic_write_text, write_json
    from rsart.evaluation.score import EvalConfig, score_submission
    from rsart.evaluation.submission import Limits, read_submission
    from rsart.io import sha256_file
    from rsart.metrics.chamfer import ChamferConfig
    from rsart import __version__

    limits = Limits(max_mesh_bytes=int(settings.max_mesh_mb * 1024 ** 2))
    gt = load_ground_truth(data_root)
    sub_file = Path(job["submission_file"])
    sub, problems = read_submission(sub_file, gt, limits)
    if not problems and sub is not None:
        problems = check_mesh_content(sub, limits, workers=1)
    if problems or sub is None:
        raise JobError(_problems_text(problems))
    for oid in gt.objects:
        resolve_states(gt.meta(oid), settings.states)
    cfg = EvalConfig(chamfer=ChamferConfig(n_samples=settings.chamfer_samples, seeds=settings.chamfer_seeds),
                     states=settings.states, limits=limits)
    results, problems = score_submission(sub, gt, cfg, workers=1)
    if problems:
        raise JobError(_problems_text(problems))
    scores = build_scores(
        results, config=cfg.to_dict(), config_hash=cfg.hash(), toolkit_version=__version__,
        dataset={"name": gt.name, "version": gt.version, "split": gt.split, "root": str(gt.root)},
        submission={"path": sub_file.name, "sha256": sha256_file(sub_file), "method": sub.method,
                    "dataset": sub.dataset})
    out = work / "jobs" / job["id"] / "eval"
    out.mkdir(parents=True, exist_ok=True)
    # scores.json + summary.md only: rsart-eval's summary.png costs ~1.5 s of matplotlib per job and the
    # site draws its own per-method plots
    write_json(out / "scores.json", scores)
    atomic_write_text(out / "summary.md", summary_markdown(scores))
    sid, _created = add_scores(engine, out, source="server", team=job["team"])
    return sid


class Lease(threading.Thread):
    """While a job is scored: refresh its lease every ``HEARTBEAT_S``; end the process if the parent is gone."""

    def __init__(self, engine, job: dict, parent_pid: int | None):
        super().__init__(daemon=True, name=f"lease-{job['id']}")
        self.engine, self.job, self.parent_pid = engine, job, parent_pid
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.wait(HEARTBEAT_S):
            if self.parent_pid is not None and os.getppid() != self.parent_pid:
                log.warning("server (pid %s) gone while scoring job %s: stopping; the job is re-queued when its "
                            "lease expires", self.parent_pid, self.job["id"])
                os._exit(3)  # mid-job: nothing is finished or ingested by an orphan
            try:
                heartbeat(self.engine, self.job["id"], self.job["worker"])
            except Exception as e:  # a busy database: the next beat retries (the lease allows several misses)
                log.warning("heartbeat of job %s failed: %s", self.job["id"], e)

    def __enter__(self) -> "Lease":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.done.set()
        self.join()


def run_worker(db: str, data_root: Path, work: Path, settings: ScoringSettings, name: str,
               poll_s: float = 0.3, parent_pid: int | None = None, max_idle_s: float | None = None) -> None:
    """Loop: claim → score (under a :class:`Lease`) → finish. Stops when the parent process is gone (or after
    ``max_idle_s`` idle); while idle, re-queues jobs whose lease expired."""
    engine = open_engine(db)
    idle_since = time.monotonic()
    next_recover = 0.0
    while True:
        if parent_pid is not None and os.getppid() != parent_pid:
            return
        job = claim(engine, name)
        if job is None:
            if max_idle_s is not None and time.monotonic() - idle_since > max_idle_s:
                return
            if time.monotonic() >= next_recover:
                n = recover(engine)
                if n:
                    log.info("re-queued %d job(s) whose worker is gone (lease expired)", n)
                next_recover = time.monotonic() + LEASE_S / 2
            time.sleep(poll_s)
            continue
        try:
            with Lease(engine, job, parent_pid):
                sid = score_job(job, data_root, work, settings, engine)
            finish(engine, job["id"], submission_id=sid)
            log.info("job %s scored -> submission %s", job["id"], sid)
        except JobError as e:
            finish(engine, job["id"], error=str(e))
        except Exception as e:  # a scoring crash fails this job, not the worker
            log.error("job %s crashed: %s", job["id"], traceback.format_exc())
            finish(engine, job["id"], error=f"internal error while scoring: {type(e).__name__}: {e}")
        idle_since = time.monotonic()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m leaderboards.worker")
    p.add_argument("--db", required=True)
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--work", type=Path, required=True)
    p.add_argument("--name", default=f"worker-{os.getpid()}")
    p.add_argument("--parent-pid", type=int)
    p.add_argument("--chamfer-samples", type=int, default=10000)
    p.add_argument("--chamfer-seeds", default="0,1,2")
    p.add_argument("--states", default="start,end")
    p.add_argument("--max-mesh-mb", type=float, default=200.0)
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    s = ScoringSettings(a.chamfer_samples, tuple(int(x) for x in a.chamfer_seeds.split(",")), a.states,
                        a.max_mesh_mb)
    try:
        run_worker(a.db, a.data, a.work, s, a.name, parent_pid=a.parent_pid)
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
