"""Ingest rsart-eval outputs into the result store, and read them back for tables and pages.

``add_scores(engine, SCORES_DIR)`` reads ``scores.json`` (format ``rsart-scores/1``) and writes one
submission with its per-object / per-part / per-state scores and the per-category aggregates. It is
idempotent: a submission's identity (``key``) is the SHA-256 of the submission file's hash, the
eval-config hash, the dataset name/version/split and the toolkit version, so the same scores ingested
twice give one entry.
"""
from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rsart.errors import RsartError
from sqlalchemy import insert, select
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError

from . import schema as S
from .tracks import derive_track

SCORES_FORMAT = "rsart-scores/1"
STATE_SUFFIXES = ("_start", "_end")
CHAMFER = ("cd_s", "cd_m", "cd_w")


class StoreError(RsartError):
    """Bad input to the store (names the file and field)."""


@dataclass
class SubmissionRow:
    """A stored submission and its aggregates: ``agg[category][metric] = (value|None, n, n_failed)``."""

    id: int
    method_name: str
    method_version: str
    method: dict
    team: str | None
    toolkit_version: str
    config_hash: str
    dataset_name: str
    dataset_version: str
    split: str
    track: dict[str, str]
    n_objects: int
    n_failed_objects: int
    source: str
    created_at: float
    agg: dict[str, dict[str, tuple[float | None, int, int]]] = field(default_factory=dict)
    scorer_version: str = "0"
    #: ``pen[category][metric] = (penalised mean|None, completion|None)`` (docs/evaluation.md §4.1)
    pen: dict[str, dict[str, tuple[float | None, float | None]]] = field(default_factory=dict)
    run_label: str | None = None
    run_config_hash: str | None = None
    units: str | None = None
    completion: float | None = None
    objects: frozenset[str] = frozenset()

    @property
    def dataset_label(self) -> str:
        """Dataset, split and scorer version: the site ranks rows only within one label, so rows scored by
        different scorer versions are never ranked together."""
        return (f"{self.dataset_name} v{self.dataset_version}" + (f" ({self.split})" if self.split else "")
                + f" · scorer {self.scorer_version}")

    @property
    def run(self) -> str:
        """The run's label: the one given, else ``#<submission id>``."""
        return self.run_label or f"#{self.id}"


def _need(doc: dict, path: Path, *keys: str) -> Any:
    cur: Any = doc
    for i, k in enumerate(keys):
        if not isinstance(cur, dict) or k not in cur:
            raise StoreError(f"{path}: missing field {'.'.join(keys[:i + 1])}")
        cur = cur[k]
    return cur


def read_scores(path: str | Path) -> tuple[dict, Path]:
    """Load ``scores.json`` from a scores folder (or the file itself); checks the fields the store uses."""
    p = Path(path)
    f = p / "scores.json" if p.is_dir() else p
    if not f.is_file():
        raise StoreError(f"{f}: no scores.json (run rsart-eval first)")
    try:
        doc = json.loads(f.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise StoreError(f"{f}: not a JSON file: {e}") from None
    if not isinstance(doc, dict) or doc.get("format") != SCORES_FORMAT:
        raise StoreError(f"{f}: format is not {SCORES_FORMAT!r}")
    for keys in (("toolkit", "version"), ("config_hash",), ("dataset", "name"), ("submission", "sha256"),
                 ("submission", "method"), ("aggregate", "categories"), ("aggregate", "overall"), ("objects",)):
        _need(doc, f, *keys)
    if not isinstance(doc["submission"]["method"], dict) or not str(doc["submission"]["method"].get("name", "")):
        raise StoreError(f"{f}: submission.method.name is missing")
    return doc, f


def submission_key(doc: dict) -> str:
    ds = doc["dataset"]
    ident = {"submission": doc["submission"]["sha256"], "config": doc["config_hash"],
             "dataset": [ds.get("name"), str(ds.get("version", "")), ds.get("split") or ""],
             "toolkit": [doc["toolkit"].get("name", "rsart"), doc["toolkit"]["version"]]}
    if "scorer_version" in doc["toolkit"]:  # absent in older scores.json: their keys stay as they were
        ident["scorer"] = str(doc["toolkit"]["scorer_version"])
    return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()


def split_metric(name: str) -> tuple[str, str]:
    """``cd_s_start`` → (cd_s, start); ``cd_s`` → (cd_s, mean); ``cd_s@m0`` → (cd_s, m0); else (name, "")."""
    if "@" in name:
        base, state = name.split("@", 1)
        return base, state
    for suf in STATE_SUFFIXES:
        if name.endswith(suf) and name[: -len(suf)] in CHAMFER:
            return name[: -len(suf)], suf[1:]
    return name, ("mean" if name in CHAMFER else "")


#: Keys of the ``method`` block that name a run rather than configure it (left out of the config hash).
RUN_LABEL_KEYS = ("run", "run_label")


def run_label_of(method: dict) -> str | None:
    """``method.run`` (or ``method.run_label``) when it is a non-empty string."""
    for k in RUN_LABEL_KEYS:
        v = method.get(k)
        if isinstance(v, str) and v.strip():
            return v.strip()[:200]
    return None


def run_config_hash(method: dict) -> str:
    """SHA-256 of the canonical JSON of the ``method`` block without its name and run label: two runs with
    the same settings (version, inputs, poses, states, options such as PD²GS's ``discovery`` block) share it."""
    cfg = {k: v for k, v in method.items() if k not in ("name", *RUN_LABEL_KEYS)}
    return hashlib.sha256(json.dumps(cfg, sort_keys=True, separators=(",", ":"), default=str).encode()).hexdigest()


def units_of(doc: dict) -> str:
    """The scored objects' units: their common ``units`` ("m", or "" for unitless scene units), else "mixed"."""
    us = {str(r.get("units") or "") for r in doc["objects"].values() if isinstance(r, dict)}
    return us.pop() if len(us) == 1 else ("mixed" if us else "")


def _finite(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def score_rows(doc: dict) -> list[dict]:
    """Long rows (object, part, metric, state, value|failure) from ``doc['objects']``."""
    rows: list[dict] = []

    def put(oid, cat, pidx, pname, metrics, by_state, failures):
        for k, v in {**metrics, **by_state}.items():
            m, s = split_metric(k)
            rows.append(dict(object_id=oid, category=cat, part_index=pidx, part_name=pname, metric=m, state=s,
                             value=_finite(v), failed=False, reason=None))
        for k, why in failures.items():
            m, s = split_metric(k)
            rows.append(dict(object_id=oid, category=cat, part_index=pidx, part_name=pname, metric=m, state=s,
                             value=None, failed=True, reason=str(why)))

    for oid, r in doc["objects"].items():
        cat = str(r.get("category", ""))
        put(oid, cat, None, None, r.get("metrics", {}), r.get("chamfer_by_state", {}), r.get("failures", {}))
        for p in r.get("parts", []):
            put(oid, cat, int(p["movable_index"]), p.get("name"), p.get("metrics", {}),
                p.get("chamfer_by_state", {}), p.get("failures", {}))
    return rows


def aggregate_rows(doc: dict) -> list[dict]:
    rows = []
    for cat, c in doc["aggregate"]["categories"].items():
        for m, a in c["metrics"].items():
            rows.append(dict(category=cat, metric=m, value=_finite(a.get("mean")), n=int(a.get("n", 0)),
                             n_failed=int(a.get("n_failed", 0)), penalised=_finite(a.get("penalised_mean")),
                             completion=_finite(a.get("completion"))))
    for m, a in doc["aggregate"]["overall"]["mean_of_categories"].items():
        rows.append(dict(category=S.MEAN, metric=m, value=_finite(a.get("mean")), n=int(a.get("n_categories", 0)),
                         n_failed=int(a.get("n_failed", 0)), penalised=_finite(a.get("penalised_mean")),
                         completion=_finite(a.get("completion"))))
    return rows


def _method_id(conn, name: str) -> int:
    got = conn.execute(select(S.methods.c.id).where(S.methods.c.name == name)).scalar()
    if got is not None:
        return int(got)
    return int(conn.execute(insert(S.methods).values(name=name, created_at=time.time())).inserted_primary_key[0])


def add_scores(engine: Engine, path: str | Path, *, source: str = "cli", team: str | None = None,
               label: str | None = None) -> tuple[int, bool]:
    """Ingest a scores folder → (submission id, created). Same scores again → (existing id, False).

    ``label`` names the run (default: the method block's ``run``, else none; pages then show ``#<id>``)."""
    doc, f = read_scores(path)
    key = submission_key(doc)
    with engine.connect() as conn:
        got = conn.execute(select(S.submissions.c.id).where(S.submissions.c.key == key)).scalar()
    if got is not None:
        return int(got), False
    method = doc["submission"]["method"]
    track = derive_track(method)
    ds = doc["dataset"]
    overall = doc["aggregate"]["overall"]
    try:
        with engine.begin() as conn:
            mid = _method_id(conn, str(method["name"]))
            sid = conn.execute(insert(S.submissions).values(
                key=key, method_id=mid, method_name=str(method["name"]), method_version=str(method.get("version", "")),
                method_json=json.dumps(method, sort_keys=True), toolkit_name=str(doc["toolkit"].get("name", "rsart")),
                toolkit_version=str(doc["toolkit"]["version"]), config_hash=str(doc["config_hash"]),
                scorer_version=str(doc["toolkit"].get("scorer_version", "0")),
                config_json=json.dumps(doc.get("config", {}), sort_keys=True), dataset_name=str(ds["name"]),
                dataset_version=str(ds.get("version", "")), split=str(ds.get("split") or ""),
                submission_sha256=str(doc["submission"]["sha256"]), track_camera_poses=track.camera_poses,
                track_states=track.states, track_part_count=track.part_count, track_inputs=track.inputs,
                n_objects=int(overall.get("n_objects", len(doc["objects"]))),
                n_failed_objects=int(overall.get("n_failed_objects", 0)), team=team, source=source,
                created_at=time.time(), run_label=(label.strip()[:200] if label and label.strip() else None)
                or run_label_of(method), run_config_hash=run_config_hash(method), units=units_of(doc),
                completion=_finite(overall.get("completion"))
                if "completion" in overall else _completion(overall, doc))).inserted_primary_key[0]
            rows = score_rows(doc)
            if rows:
                conn.execute(insert(S.scores), [dict(r, submission_id=sid) for r in rows])
            conn.execute(insert(S.aggregates), [dict(r, submission_id=sid) for r in aggregate_rows(doc)])
    except IntegrityError:  # a concurrent ingest of the same scores won the race
        with engine.connect() as conn:
            got = conn.execute(select(S.submissions.c.id).where(S.submissions.c.key == key)).scalar()
        if got is None:
            raise
        return int(got), False
    return int(sid), True


def _completion(overall: dict, doc: dict) -> float | None:
    n = int(overall.get("n_objects", len(doc["objects"])))
    return (n - int(overall.get("n_failed_objects", 0))) / n if n else None


def list_submissions(engine: Engine) -> list[SubmissionRow]:
    """Every submission with its aggregates, oldest first."""
    with engine.connect() as conn:
        subs = conn.execute(select(S.submissions).order_by(S.submissions.c.id)).mappings().all()
        aggs = conn.execute(select(S.aggregates.c.submission_id, S.aggregates.c.category, S.aggregates.c.metric,
                                   S.aggregates.c.value, S.aggregates.c.n, S.aggregates.c.n_failed,
                                   S.aggregates.c.penalised, S.aggregates.c.completion)).all()
        objs = conn.execute(select(S.scores.c.submission_id, S.scores.c.object_id).distinct()).all()
    by: dict[int, dict] = {}
    pen: dict[int, dict] = {}
    for sid, cat, m, v, n, nf, pv, comp in aggs:
        by.setdefault(sid, {}).setdefault(cat, {})[m] = (v, n, nf)
        pen.setdefault(sid, {}).setdefault(cat, {})[m] = (pv, comp)
    objects: dict[int, set[str]] = {}
    for sid, oid in objs:
        objects.setdefault(sid, set()).add(oid)
    out = []
    for s in subs:
        out.append(SubmissionRow(
            id=s["id"], method_name=s["method_name"], method_version=s["method_version"],
            method=json.loads(s["method_json"]), team=s["team"], toolkit_version=s["toolkit_version"],
            config_hash=s["config_hash"], dataset_name=s["dataset_name"], dataset_version=s["dataset_version"],
            split=s["split"], track={"camera_poses": s["track_camera_poses"], "states": s["track_states"],
                                     "part_count": s["track_part_count"], "inputs": s["track_inputs"]},
            n_objects=s["n_objects"], n_failed_objects=s["n_failed_objects"], source=s["source"],
            created_at=s["created_at"], agg=by.get(s["id"], {}), scorer_version=s["scorer_version"],
            pen=pen.get(s["id"], {}), run_label=s["run_label"], run_config_hash=s["run_config_hash"],
            units=s["units"], completion=s["completion"], objects=frozenset(objects.get(s["id"], ()))))
    return out


def count_submissions(engine: Engine) -> int:
    from sqlalchemy import func

    with engine.connect() as conn:
        return int(conn.execute(select(func.count()).select_from(S.submissions)).scalar() or 0)
