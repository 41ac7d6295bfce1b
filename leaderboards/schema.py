"""The result store's tables (SQLAlchemy Core) and engine set-up.

Tables: ``methods``; ``submissions`` (method block, toolkit version, eval-config hash, dataset name/version/
split, track, team); ``scores`` (one row per object / part / metric / state: a value, or a failure with
its reason); ``aggregates`` (per category and the Mean over categories, as rsart-eval computes them);
and the server's ``tokens`` (SHA-256 of each token, never the token), ``jobs`` (the durable queue, with each
running job's ``heartbeat_at`` lease) and ``upload_attempts`` (what the per-token rate limit counts).

``open_engine(url)`` accepts any SQLAlchemy URL or a plain file path (→ SQLite). SQLite runs in WAL mode
with a busy timeout, so the server and its worker processes can share one file.
"""
from __future__ import annotations

from pathlib import Path

from sqlalchemy import (Boolean, Column, Float, ForeignKey, Index, Integer, MetaData, String, Table, Text,
                        create_engine, event)
from sqlalchemy.engine import Engine

metadata = MetaData()

methods = Table(
    "methods", metadata,
    Column("id", Integer, primary_key=True),
    Column("name", String(200), nullable=False, unique=True),
    Column("created_at", Float, nullable=False),
)

submissions = Table(
    "submissions", metadata,
    Column("id", Integer, primary_key=True),
    Column("key", String(64), nullable=False, unique=True),  # identity: same scores -> same key
    Column("method_id", Integer, ForeignKey("methods.id"), nullable=False),
    Column("method_name", String(200), nullable=False),
    Column("method_version", String(200), nullable=False),
    Column("method_json", Text, nullable=False),
    Column("toolkit_name", String(100), nullable=False),
    Column("toolkit_version", String(100), nullable=False),
    # scores.json toolkit.scorer_version ("0" = scored before versions were recorded); never ranked across
    Column("scorer_version", String(20), nullable=False, server_default="0"),
    Column("config_hash", String(64), nullable=False),
    Column("config_json", Text, nullable=False),
    Column("dataset_name", String(200), nullable=False),
    Column("dataset_version", String(100), nullable=False),
    Column("split", String(100), nullable=False),  # "" = every object of the dataset
    Column("submission_sha256", String(64), nullable=False),
    Column("track_camera_poses", String(40), nullable=False),
    Column("track_states", String(40), nullable=False),
    Column("track_part_count", String(40), nullable=False),
    Column("track_inputs", String(40), nullable=False),
    Column("n_objects", Integer, nullable=False),
    Column("n_failed_objects", Integer, nullable=False),
    Column("team", String(200)),
    Column("source", String(40), nullable=False),  # "cli" | "server" | "synthetic"
    Column("created_at", Float, nullable=False),
    Column("run_label", String(200)),        # the run's name (method.run / --label); NULL = none given
    Column("run_config_hash", String(64)),   # SHA-256 of the method block's settings (store.run_config_hash)
    Column("units", String(40)),             # the scored objects' units ("m", "" unitless, "mixed")
    Column("completion", Float),             # share of objects that are not null
)
Index("ix_submissions_dataset", submissions.c.dataset_name, submissions.c.dataset_version)

scores = Table(
    "scores", metadata,
    Column("id", Integer, primary_key=True),
    Column("submission_id", Integer, ForeignKey("submissions.id", ondelete="CASCADE"), nullable=False),
    Column("object_id", String(200), nullable=False),
    Column("category", String(200), nullable=False),
    Column("part_index", Integer),        # true movable index; NULL = object level
    Column("part_name", String(200)),
    Column("metric", String(60), nullable=False),   # cd_s, cd_m, axis_ang, ...
    Column("state", String(100), nullable=False),   # "start" | "end" | "mean" | a state id | "" (no state)
    Column("value", Float),               # NULL when failed
    Column("failed", Boolean, nullable=False),
    Column("reason", Text),
)
Index("ix_scores_submission", scores.c.submission_id)

aggregates = Table(
    "aggregates", metadata,
    Column("id", Integer, primary_key=True),
    Column("submission_id", Integer, ForeignKey("submissions.id", ondelete="CASCADE"), nullable=False),
    Column("category", String(200), nullable=False),  # a category, or MEAN (mean over categories)
    Column("metric", String(60), nullable=False),
    Column("value", Float),
    Column("n", Integer, nullable=False),
    Column("n_failed", Integer, nullable=False),
    Column("penalised", Float),    # the penalised mean (failures at the worst value; docs/evaluation.md §4.1)
    Column("completion", Float),   # objects scored without failure / objects where the metric applies
)
Index("ix_aggregates_submission", aggregates.c.submission_id)

tokens = Table(
    "tokens", metadata,
    Column("id", Integer, primary_key=True),
    Column("team", String(200), nullable=False),
    Column("token_sha256", String(64), nullable=False, unique=True),
    Column("rate_per_hour", Integer, nullable=False),
    Column("created_at", Float, nullable=False),
    Column("revoked", Boolean, nullable=False, default=False),
)

jobs = Table(
    "jobs", metadata,
    Column("id", String(32), primary_key=True),
    Column("token_id", Integer, ForeignKey("tokens.id"), nullable=False),
    Column("team", String(200), nullable=False),
    Column("status", String(20), nullable=False),  # queued | running | done | failed
    Column("folder", Text, nullable=False),        # extracted submission folder (under the work dir)
    Column("submission_file", Text, nullable=False),
    Column("method_name", String(200)),
    Column("attempts", Integer, nullable=False, default=0),
    Column("worker", String(100)),
    Column("error", Text),
    Column("submission_id", Integer),
    Column("created_at", Float, nullable=False),
    Column("started_at", Float),
    Column("finished_at", Float),
    Column("heartbeat_at", Float),  # the running worker's lease: refreshed every few seconds while it scores
)
Index("ix_jobs_status", jobs.c.status, jobs.c.created_at)
Index("ix_jobs_token", jobs.c.token_id, jobs.c.created_at)

upload_attempts = Table(  # every upload attempt, accepted or refused: the per-token rate limit counts these
    "upload_attempts", metadata,
    Column("id", Integer, primary_key=True),
    Column("token_id", Integer, ForeignKey("tokens.id"), nullable=False),
    Column("created_at", Float, nullable=False),
)
Index("ix_upload_attempts_token", upload_attempts.c.token_id, upload_attempts.c.created_at)

MEAN = "__mean__"


def normalize_url(url: str) -> str:
    """A SQLAlchemy URL as given, or ``sqlite:///<absolute path>`` for a plain file path."""
    if "://" in url:
        return url
    return "sqlite:///" + str(Path(url).expanduser().resolve())


def sqlite_path(url: str) -> Path | None:
    """The database file of a SQLite URL (None for other back ends or in-memory SQLite)."""
    url = normalize_url(url)
    if not url.startswith("sqlite:///") or url == "sqlite:///:memory:":
        return None
    return Path(url[len("sqlite:///"):])


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute("PRAGMA busy_timeout=60000")
    cur.execute("PRAGMA foreign_keys=ON")
    cur.close()


def open_engine(url: str, create: bool = True) -> Engine:
    """Engine for ``url`` (see module docstring); creates missing tables when ``create``."""
    url = normalize_url(url)
    path = sqlite_path(url)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={"timeout": 60})
        event.listen(engine, "connect", _sqlite_pragmas)
    else:
        engine = create_engine(url, pool_pre_ping=True)
    if create:
        metadata.create_all(engine)
        _add_scorer_version(engine)
        _add_job_lease_column(engine)
        _add_missing_columns(engine)
    return engine


def _add_scorer_version(engine: Engine) -> None:
    """Stores made before scorer versions were recorded get the column (their rows read as version "0")."""
    from sqlalchemy import inspect, text

    if "scorer_version" not in {c["name"] for c in inspect(engine).get_columns("submissions")}:
        with engine.begin() as conn:
            conn.execute(text("ALTER TABLE submissions ADD COLUMN scorer_version VARCHAR(20) NOT NULL DEFAULT '0'"))


def _add_job_lease_column(engine: Engine) -> None:
    """Queues made before job leases get the ``jobs.heartbeat_at`` column (create_all adds only tables)."""
    from sqlalchemy import inspect, text

    have = {c["name"] for c in inspect(engine).get_columns("jobs")}
    if "heartbeat_at" not in have:
        try:
            with engine.begin() as c:
                c.execute(text("ALTER TABLE jobs ADD COLUMN heartbeat_at FLOAT"))
        except Exception:  # another process added it first
            if "heartbeat_at" not in {c["name"] for c in inspect(engine).get_columns("jobs")}:
                raise


def _add_missing_columns(engine: Engine) -> None:
    """Bring a store written by an older rsart up to date: add the nullable columns it lacks (no data is
    changed; older submissions show those fields as unknown)."""
    from sqlalchemy import inspect, text

    insp = inspect(engine)
    for t in (submissions, aggregates):
        have = {c["name"] for c in insp.get_columns(t.name)}
        missing = [c for c in t.columns if c.name not in have and c.nullable]
        for c in missing:
            try:
                with engine.begin() as conn:
                    conn.execute(text(f"ALTER TABLE {t.name} ADD COLUMN {c.name} "
                                      f"{c.type.compile(dialect=engine.dialect)}"))
            except Exception:  # another process added it first
                if c.name not in {x["name"] for x in inspect(engine).get_columns(t.name)}:
                    raise
