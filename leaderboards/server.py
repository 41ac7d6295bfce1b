"""``rsart leaderboard serve``: the submission server (FastAPI on uvicorn) and its live leaderboard page.

API (docs/leaderboard.md):

* ``POST /api/submissions`` — header ``Authorization: Bearer <token>``, multipart field ``archive`` = a zip
  holding ``submission.json`` and its meshes → ``202 {"job_id", "status": "queued"}``. Errors: 401 (no or
  bad token), 411 (no Content-Length), 413 (too large), 422 (unsafe archive or invalid submission, with
  ``problems`` listing each JSON path), 429 (rate limit; ``Retry-After``).
* ``GET /api/jobs/{id}`` — ``queued | running | done | failed`` (+ ``error`` / ``submission_id``).
* ``GET /api/leaderboard`` — computed rows as JSON; ``GET /api/version`` — counts and a ``key`` the live
  page polls; it reloads when the key differs from the one stamped into it (``<meta name=rsart-live-version>``).
* ``GET /`` — the live leaderboard (same tables as the static site; reloads when a new score lands).

Uploads are written atomically (temp + rename) under ``<work>/``; the queue is the database's ``jobs``
table, so a crash or restart loses nothing. Uploads are received, unpacked and validated in the server's
own staging folder (:func:`incoming_dir`) and moved into ``<work>/jobs/<id>/`` just before being queued. At
start-up the server removes its own leftovers of a crash (:func:`clean_work`: everything in its staging
folder, i.e. ``<id>.zip`` files and ``.partial`` extraction folders, and job folders never queued) and
re-queues jobs whose worker is gone (expired lease, :mod:`leaderboards.jobs`). Every upload attempt counts
toward the per-token rate limit, and at most ``max_unpacking`` archives are inflated at once.

The app is three routers (:func:`submissions_router`, :func:`api_router`, :func:`pages_router`) sharing one
:class:`AppState`, behind the :class:`BodyLimit` middleware.
"""
from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fastapi import APIRouter, FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import HTMLResponse, JSONResponse

from . import jobs as J
from .archive import ArchiveError, ArchiveLimits, extract_zip, find_submission_file
from .html import esc, page
from .schema import MEAN, open_engine
from .store import count_submissions, list_submissions
from .worker import ScoringSettings

UPLOAD_PATH = "/api/submissions"

#: The live page's version stamp: ``<meta name="rsart-live-version" content="KEY">``, KEY as in /api/version.
VERSION_META = "rsart-live-version"

# The live page polls api/version and reloads when the key differs from the one the server stamped into the
# page when it rendered it. (Taking the baseline from the first poll instead loses every score that lands
# between the render and that poll: the page then never reloads.)
LIVE_JS = """
(function(){var m=document.querySelector('meta[name=%s]'),seen=m?m.getAttribute('content'):null,n=0;
function tick(){if(++n>2400)return;fetch('api/version',{cache:'no-store'}).then(function(r){return r.json();})
.then(function(v){if(v.key!==seen){location.reload();return;}setTimeout(tick,1500);})
.catch(function(){setTimeout(tick,3000);});}setTimeout(tick,1500);})();
""" % VERSION_META


def live_version(engine) -> dict:
    """What the live page polls: scored submissions, done jobs, the queue, and ``key`` (changes whenever a
    scored submission lands)."""
    q = J.queue_counts(engine)
    n, done = count_submissions(engine), q.get("done", 0)
    return {"submissions": n, "done": done, "queue": q, "key": f"{n}:{done}"}


@dataclass(frozen=True)
class ServerConfig:
    db: str
    data: Path
    work: Path
    archive: ArchiveLimits = ArchiveLimits()
    scoring: ScoringSettings = ScoringSettings()
    max_unpacking: int = 2   # archives inflated and validated at once (the others wait their turn)


def _error(status: int, message: str, problems: list | None = None, headers: dict | None = None) -> JSONResponse:
    body: dict = {"error": message}
    if problems is not None:
        body["problems"] = problems
    return JSONResponse(body, status_code=status, headers=headers)


class BodyLimit:
    """ASGI middleware: uploads need a Content-Length (411) no larger than the limit (413), checked before
    any byte of the body is read; uvicorn enforces the declared length, so the body cannot exceed it."""

    def __init__(self, app, limit: int):
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):
        if scope["type"] == "http" and scope["path"] == UPLOAD_PATH and scope["method"] == "POST":
            hdr = dict(scope["headers"]).get(b"content-length")
            resp = None
            if hdr is None:
                resp = _error(411, "Content-Length is required for uploads")
            elif not hdr.isdigit() or int(hdr) > self.limit:
                resp = _error(413, f"upload too large: {hdr.decode(errors='replace')} bytes; the limit is {self.limit}")
            if resp is not None:
                await resp(scope, receive, send)
                return
        await self.app(scope, receive, send)


@dataclass
class AppState:
    """What the routers share: the config, the store, the ground truth and the upload bookkeeping."""

    cfg: ServerConfig
    engine: Any
    gt: Any
    limits: Any                      # rsart.evaluation.submission.Limits for reading uploaded submissions
    rate_lock: threading.Lock        # record + count an attempt atomically
    unpack_slots: threading.Semaphore  # at most cfg.max_unpacking archives inflated at once

    def auth(self, request: Request) -> dict | None:
        h = request.headers.get("authorization", "")
        if not h.lower().startswith("bearer "):
            return None
        return J.lookup_token(self.engine, h[7:].strip())


def submissions_router(st: AppState) -> APIRouter:
    """``POST /api/submissions`` (upload → validate → queue) and ``GET /api/jobs/{id}``."""
    from rsart.evaluation.submission import read_submission

    r = APIRouter()
    cfg = st.cfg

    def _validate(job_id: str, zip_path: Path) -> tuple[Path, Path, str]:
        """Unpack and validate in this server's staging folder, then move the job folder into ``jobs/``."""
        staging = incoming_dir(cfg) / job_id
        folder = staging / "submission"
        staging.mkdir(parents=True, exist_ok=True)
        try:
            with st.unpack_slots:  # inflating is the expensive, attacker-driven part: a bounded number at once
                extract_zip(zip_path, folder, cfg.archive)
            sub_file = find_submission_file(folder)
            sub, problems = read_submission(sub_file, st.gt, st.limits)
            if problems or sub is None:
                raise _Invalid(problems)
            final = cfg.work / "jobs" / job_id
            os.replace(staging, final)
            return final / "submission", final / sub_file.relative_to(staging), str(sub.method.get("name", ""))
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        finally:
            zip_path.unlink(missing_ok=True)

    @r.post(UPLOAD_PATH)
    async def upload(request: Request):
        token = st.auth(request)
        if token is None:
            return _error(401, "missing or invalid token (header: Authorization: Bearer <token>)",
                          headers={"WWW-Authenticate": "Bearer"})
        with st.rate_lock:  # every attempt counts, accepted or refused (a refused archive costs work too)
            n = J.record_attempt(st.engine, token["id"])
        if n > token["rate_per_hour"]:
            return _error(429, f"rate limit: {token['rate_per_hour']} uploads per hour for this token",
                          headers={"Retry-After": "3600"})
        ctype = request.headers.get("content-type", "")
        if not ctype.startswith("multipart/form-data"):
            return _error(422, "send the zip as multipart/form-data field 'archive'")
        form = await request.form(max_files=1, max_fields=4)
        up = form.get("archive")
        if up is None or isinstance(up, str):
            await form.close()
            return _error(422, "multipart field 'archive' (the zip file) is missing")
        job_id = J.new_job_id()
        part = incoming_dir(cfg) / f"{job_id}.zip.partial"
        dest = incoming_dir(cfg) / f"{job_id}.zip"
        try:
            with open(part, "wb") as f:
                await run_in_threadpool(shutil.copyfileobj, up.file, f, 1 << 20)
                f.flush()
                os.fsync(f.fileno())
            os.replace(part, dest)
        finally:
            part.unlink(missing_ok=True)
            await form.close()
        try:
            folder, sub_file, method = await run_in_threadpool(_validate, job_id, dest)
        except ArchiveError as e:
            return _error(422, f"unsafe or unusable archive: {e}")
        except _Invalid as e:  # server folders are cut from the messages: paths are relative to the archive
            root = str(incoming_dir(cfg) / job_id / "submission") + os.sep
            return _error(422, f"invalid submission: {len(e.problems)} problem(s)",
                          problems=[{"path": p.path, "message": p.message.replace(root, "")} for p in e.problems])
        J.enqueue(st.engine, job_id, token, str(folder), str(sub_file), method)
        return JSONResponse({"job_id": job_id, "status": "queued", "method": method}, status_code=202)

    @r.get("/api/jobs/{job_id}")
    def job_status(job_id: str):
        j = J.get_job(st.engine, job_id) if job_id.isalnum() else None
        if j is None:
            return _error(404, f"no job {job_id!r}")
        return {k: j[k] for k in ("id", "status", "error", "submission_id", "method_name", "team", "attempts")}

    return r


def api_router(st: AppState) -> APIRouter:
    """The JSON read API: ``/api/version`` (what the live page polls), ``/api/leaderboard``, ``/healthz``."""
    r = APIRouter()

    @r.get("/api/version")
    def version():
        return live_version(st.engine)

    @r.get("/api/leaderboard")
    def leaderboard():
        return [{"id": s.id, "method": s.method_name, "version": s.method_version, "team": s.team,
                 "dataset": s.dataset_label, "track": s.track, "n_objects": s.n_objects,
                 "n_failed_objects": s.n_failed_objects, "run": s.run, "run_config_hash": s.run_config_hash,
                 "scorer_version": s.scorer_version, "completion": s.completion,
                 "mean": {m: {"value": v, "n": n, "n_failed": nf,
                              "penalised": s.pen.get(MEAN, {}).get(m, (None, None))[0],
                              "completion": s.pen.get(MEAN, {}).get(m, (None, None))[1]}
                          for m, (v, n, nf) in s.agg.get(MEAN, {}).items()}}
                for s in list_submissions(st.engine)]

    @r.get("/healthz")
    def healthz():
        return {"ok": True}

    return r


def pages_router(st: AppState) -> APIRouter:
    """HTML: the live leaderboard (``/``) and the static site's pages that make sense live."""
    r = APIRouter()

    @r.get("/", response_class=HTMLResponse)
    def live():
        from .exports import index_body

        # stamp first, then read: a score landing in between is shown and then costs one extra reload,
        # never a missed one
        stamp = live_version(st.engine)["key"]
        body = ('<p class="note">Live page: reloads when a new submission is scored. Upload: '
                '<code>curl -H "Authorization: Bearer $TOKEN" -F archive=@sub.zip HOST/api/submissions</code>.</p>'
                + index_body(st.engine, list_submissions(st.engine)))
        head = f'<meta name="{VERSION_META}" content="{esc(stamp)}">'
        return page("rsart leaderboard (live)", body, extra_head=head, extra_js=LIVE_JS)

    @r.get("/published.html", response_class=HTMLResponse)
    def published():
        from .exports import published_page

        return published_page()

    @r.get("/metrics.html", response_class=HTMLResponse)
    def metrics():
        from .site import metrics_page

        return metrics_page()

    @r.get("/methods.html", response_class=HTMLResponse)
    @r.get("/downloads.html", response_class=HTMLResponse)
    def static_only():
        return page("Static site only", "<p>Method pages, plots and the Markdown/CSV exports are part of the static "
                    "site: <code>rsart leaderboard build --db URL --out site/</code>. The JSON rows are at "
                    '<a href="api/leaderboard">api/leaderboard</a>.</p>')

    return r


def create_app(cfg: ServerConfig) -> FastAPI:
    """The ASGI app: the three routers behind the upload-size middleware."""
    from rsart.evaluation.ground_truth import load_ground_truth
    from rsart.evaluation.submission import Limits

    for d in (incoming_dir(cfg), cfg.work / "jobs"):
        d.mkdir(parents=True, exist_ok=True)
    st = AppState(cfg, open_engine(cfg.db), load_ground_truth(cfg.data),
                  Limits(max_mesh_bytes=int(cfg.scoring.max_mesh_mb * 1024 ** 2),
                         max_total_bytes=cfg.archive.max_unpacked_bytes),
                  threading.Lock(), threading.Semaphore(max(1, cfg.max_unpacking)))
    app = FastAPI(title="rsart leaderboard", docs_url=None, redoc_url=None, openapi_url=None)
    for router in (submissions_router(st), api_router(st), pages_router(st)):
        app.include_router(router)
    return BodyLimit(app, cfg.archive.max_upload_bytes + 64 * 1024)


def incoming_dir(cfg: ServerConfig) -> Path:
    """This server's own staging folder, ``<work>/incoming/<host>/``: uploads being received, unpacked and
    validated. Per host, so servers of several machines sharing one ``--work`` never remove each other's."""
    host = re.sub(r"[^A-Za-z0-9_.-]", "_", socket.gethostname()).strip(".") or "host"
    return cfg.work / "incoming" / host


def clean_work(cfg: ServerConfig, engine, unqueued_age_s: float = 60.0) -> list[Path]:
    """Remove this server's own leftovers of a crash (run at start-up, before any upload is accepted) → the
    removed paths: everything in :func:`incoming_dir` (zips being received, ``.partial`` extraction folders,
    archives being validated), and job folders the queue does not know that are older than
    ``unqueued_age_s`` (a crash between moving a validated upload into ``jobs/`` and queueing it)."""
    removed: list[Path] = []
    mine = incoming_dir(cfg)
    for p in sorted(mine.iterdir()) if mine.is_dir() else []:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        removed.append(p)
    jobs_dir = cfg.work / "jobs"
    for d in sorted(jobs_dir.iterdir()) if jobs_dir.is_dir() else []:
        if d.is_dir() and not d.is_symlink() and J.get_job(engine, d.name) is None \
                and time.time() - d.stat().st_mtime > unqueued_age_s:
            shutil.rmtree(d, ignore_errors=True)
            removed.append(d)
    return removed


class _Invalid(Exception):
    def __init__(self, problems):
        super().__init__(f"{len(problems)} problems")
        self.problems = problems


def start_workers(cfg: ServerConfig, n: int) -> list[subprocess.Popen]:
    """``n`` worker processes (python -m leaderboards.worker) that exit when this process dies."""
    s = cfg.scoring
    procs = []
    for i in range(n):
        argv = [sys.executable, "-m", "leaderboards.worker", "--db", cfg.db, "--data", str(cfg.data),
                "--work", str(cfg.work), "--name", f"w{i}-{os.getpid()}", "--parent-pid", str(os.getpid()),
                "--chamfer-samples", str(s.chamfer_samples), "--chamfer-seeds", ",".join(map(str, s.chamfer_seeds)),
                "--states", s.states, "--max-mesh-mb", str(s.max_mesh_mb)]
        procs.append(subprocess.Popen(argv, env={**os.environ, "PYTHONPATH": _pythonpath()}))
    return procs


def _pythonpath() -> str:
    root = str(Path(__file__).resolve().parent.parent)
    old = os.environ.get("PYTHONPATH", "")
    return root + (os.pathsep + old if old else "")


def serve(cfg: ServerConfig, host: str = "127.0.0.1", port: int = 8000, workers: int = 2) -> int:
    """Recover the queue, start the workers, run uvicorn until interrupted."""
    import uvicorn

    engine = open_engine(cfg.db)
    for d in (incoming_dir(cfg), cfg.work / "jobs"):
        d.mkdir(parents=True, exist_ok=True)
    removed = clean_work(cfg, engine)
    if removed:
        print(f"removed {len(removed)} leftover(s) of an interrupted run under {cfg.work}", file=sys.stderr)
    n = J.recover(engine)  # only jobs whose worker is gone (expired lease); idle workers re-check later
    if n:
        print(f"requeued {n} interrupted job(s)", file=sys.stderr)
    app = create_app(cfg)
    procs = start_workers(cfg, workers)
    try:
        uvicorn.run(app, host=host, port=port, log_level="warning", timeout_graceful_shutdown=5)
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
    return 0
