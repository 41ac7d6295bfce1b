"""Team tokens (stored as SHA-256, never in clear) and the durable scoring queue (the ``jobs`` table).

Tokens are 32 random bytes (URL-safe base64); a fast hash is enough for such high-entropy secrets (no
password stretching needed). The queue lives in the database, so a crash or restart loses nothing, and a
job is claimed with one atomic UPDATE, so two workers never take the same job.

Leases: a worker refreshes its running job's ``heartbeat_at`` every ``HEARTBEAT_S`` seconds
(:func:`heartbeat`). :func:`recover` (run when the server starts, and by idle workers) puts a ``running``
job back in the queue only when its lease has expired (no heartbeat for ``LEASE_S``): its worker is really
gone. A worker orphaned by a server crash is still scoring for a moment, so a restart does not hand its
job to a second worker; the orphan notices its parent is gone within a heartbeat and stops, and the job
is re-queued when its lease expires.

Rate limit: every upload attempt is recorded (:func:`record_attempt`), accepted or refused, and counted.
"""
from __future__ import annotations

import hashlib
import secrets
import time
import uuid

from sqlalchemy import and_, func, insert, select, update
from sqlalchemy.engine import Engine

from . import schema as S

MAX_ATTEMPTS = 3
HEARTBEAT_S = 1.0   # a scoring worker refreshes its lease this often
LEASE_S = 10.0      # a running job whose lease is older than this has lost its worker


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def create_token(engine: Engine, team: str, rate_per_hour: int = 20) -> str:
    """A new token for ``team`` (returned once, stored hashed)."""
    token = secrets.token_urlsafe(32)
    with engine.begin() as c:
        c.execute(insert(S.tokens).values(team=team, token_sha256=hash_token(token), rate_per_hour=int(rate_per_hour),
                                          created_at=time.time(), revoked=False))
    return token


def lookup_token(engine: Engine, token: str) -> dict | None:
    """The token's row (id, team, rate_per_hour) if valid and not revoked."""
    with engine.connect() as c:
        row = c.execute(select(S.tokens).where(S.tokens.c.token_sha256 == hash_token(token))).mappings().first()
    if row is None or row["revoked"]:
        return None
    return dict(row)


def revoke_team(engine: Engine, team: str) -> int:
    with engine.begin() as c:
        return c.execute(update(S.tokens).where(S.tokens.c.team == team).values(revoked=True)).rowcount


def record_attempt(engine: Engine, token_id: int) -> int:
    """Record one upload attempt of ``token_id`` → attempts in the last hour, this one included."""
    now = time.time()
    with engine.begin() as c:
        c.execute(insert(S.upload_attempts).values(token_id=token_id, created_at=now))
        c.execute(S.upload_attempts.delete().where(S.upload_attempts.c.created_at < now - 3600))
        return int(c.execute(select(func.count()).select_from(S.upload_attempts).where(and_(
            S.upload_attempts.c.token_id == token_id, S.upload_attempts.c.created_at > now - 3600))).scalar() or 0)


def enqueue(engine: Engine, job_id: str, token: dict, folder: str, submission_file: str, method_name: str) -> None:
    with engine.begin() as c:
        c.execute(insert(S.jobs).values(id=job_id, token_id=token["id"], team=token["team"], status="queued",
                                        folder=folder, submission_file=submission_file, method_name=method_name,
                                        attempts=0, created_at=time.time()))


def new_job_id() -> str:
    return uuid.uuid4().hex


def claim(engine: Engine, worker: str) -> dict | None:
    """Atomically take the oldest queued job (→ its row, now ``running``), or None."""
    claim_id = f"{worker}:{uuid.uuid4().hex[:8]}"
    oldest = (select(S.jobs.c.id).where(S.jobs.c.status == "queued").order_by(S.jobs.c.created_at, S.jobs.c.id)
              .limit(1).scalar_subquery())
    with engine.begin() as c:
        n = c.execute(update(S.jobs).where(and_(S.jobs.c.id == oldest, S.jobs.c.status == "queued"))
                      .values(status="running", worker=claim_id, started_at=time.time(),
                              heartbeat_at=time.time(), attempts=S.jobs.c.attempts + 1)).rowcount
        if n != 1:
            return None
        row = c.execute(select(S.jobs).where(S.jobs.c.worker == claim_id)).mappings().first()
    return dict(row) if row else None


def finish(engine: Engine, job_id: str, *, submission_id: int | None = None, error: str | None = None) -> None:
    with engine.begin() as c:
        c.execute(update(S.jobs).where(S.jobs.c.id == job_id).values(
            status="failed" if error else "done", error=error, submission_id=submission_id, finished_at=time.time()))


def heartbeat(engine: Engine, job_id: str, worker: str) -> bool:
    """Refresh the lease of ``job_id`` held by ``worker`` (its claim id) → False when it no longer holds it."""
    with engine.begin() as c:
        return c.execute(update(S.jobs).where(and_(S.jobs.c.id == job_id, S.jobs.c.worker == worker,
                                                   S.jobs.c.status == "running"))
                         .values(heartbeat_at=time.time())).rowcount == 1


def recover(engine: Engine, lease_s: float = LEASE_S) -> int:
    """Requeue ``running`` jobs whose lease expired (no heartbeat for ``lease_s``: the worker is gone); fail
    those that already used MAX_ATTEMPTS. → requeued count."""
    now = time.time()
    stale = and_(S.jobs.c.status == "running",
                 func.coalesce(S.jobs.c.heartbeat_at, S.jobs.c.started_at, 0.0) < now - lease_s)
    with engine.begin() as c:
        c.execute(update(S.jobs).where(and_(stale, S.jobs.c.attempts >= MAX_ATTEMPTS))
                  .values(status="failed", error=f"gave up after {MAX_ATTEMPTS} interrupted attempts",
                          finished_at=now))
        return c.execute(update(S.jobs).where(stale).values(status="queued", worker=None)).rowcount


def get_job(engine: Engine, job_id: str) -> dict | None:
    with engine.connect() as c:
        row = c.execute(select(S.jobs).where(S.jobs.c.id == job_id)).mappings().first()
    return dict(row) if row else None


def queue_counts(engine: Engine) -> dict[str, int]:
    with engine.connect() as c:
        rows = c.execute(select(S.jobs.c.status, func.count()).group_by(S.jobs.c.status)).all()
    return {s: int(n) for s, n in rows}
