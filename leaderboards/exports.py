"""Markdown and CSV exports of the computed leaderboard and of the published rows, and the site build."""
from __future__ import annotations

import csv
import io
import time
from pathlib import Path

from rsart.io import atomic_dir
from sqlalchemy.engine import Engine

from . import schema as S
from .html import INFO, esc, page, present_metrics
from .paper import load_tables
from .site import (COMPARE_TABLES, _method_label, comparison_html, group_subs, latest_per_method,
                   leaderboard_sections, method_pages,
                   metrics_page, part_index_means, published_table_html)
from .store import SubmissionRow, list_submissions
from .tracks import Track


def _fmt(v: tuple | None, percent: bool) -> str:
    if v is None:
        return "·"
    val, _n, nf = v
    star = "*" if nf else ""
    if val is None:
        return "*" if star else "–"
    return f"{val * (100 if percent else 1):.3f}{star}"


def leaderboard_markdown(subs: list[SubmissionRow]) -> str:
    metrics = present_metrics(subs) if subs else []
    out = ["# rsart leaderboard (computed here)", "",
           "Mean over categories; `*` = failed on ≥1 object or part; `–` = not applicable. Published paper "
           "rows are in published.csv and are not re-run here.", ""]
    for ds, tracks in group_subs(subs).items():
        out += [f"## {ds}", ""]
        for _tk, ss in tracks.items():
            out += [f"### {Track(**ss[0].track).label()}", "",
                    "| Method | Team | Objects | " + " | ".join(INFO[k].label for k in metrics) + " |",
                    "|---|---|---:|" + "---:|" * len(metrics)]
            for s in ss:
                cells = [_fmt(s.agg.get(S.MEAN, {}).get(k), INFO[k].percent) for k in metrics]
                out.append(f"| {_method_label(s).replace('|', '/')} | {(s.team or '').replace('|', '/')} | "
                           f"{s.n_objects} ({s.n_failed_objects} failed) | " + " | ".join(cells) + " |")
            out.append("")
    return "\n".join(out) + "\n"


def leaderboard_csv(subs: list[SubmissionRow], by_category: bool) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["submission_id", "method", "version", "team", "dataset", "dataset_version", "split", "camera_poses",
                "states", "part_count", "inputs", "toolkit_version", "config_hash", "category", "metric", "value",
                "n", "n_failed", "submitted_utc"])
    for s in subs:
        for cat, ms in sorted(s.agg.items()):
            if (cat == S.MEAN) == by_category:
                continue
            for m, (v, n, nf) in sorted(ms.items()):
                w.writerow([s.id, s.method_name, s.method_version, s.team or "", s.dataset_name, s.dataset_version,
                            s.split, s.track["camera_poses"], s.track["states"], s.track["part_count"],
                            s.track["inputs"], s.toolkit_version, s.config_hash, "Mean" if cat == S.MEAN else cat, m,
                            "" if v is None else repr(v), n, nf,
                            time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(s.created_at))])
    return buf.getvalue()


def published_csv() -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["table", "label", "dataset", "group", "method", "variant", "column", "text", "value", "failed",
                "applicable", "tex_lines", "status"])
    for t in load_tables():
        for r in t.rows:
            for col, c in zip(t.columns, r.cells):
                w.writerow([t.key, t.source["label"], t.dataset, r.group or "", r.method, r.variant, col, c.text,
                            "" if c.value is None else c.value, int(c.failed), int(c.applicable),
                            f"{r.lines[0]}-{r.lines[1]}", "published, not re-run here"])
    return buf.getvalue()


def index_body(engine: Engine, subs: list[SubmissionRow], prefix: str = "") -> str:
    tables = {t.key: t for t in load_tables()}
    latest = latest_per_method(subs)
    parts = part_index_means(engine, [s.id for s in latest])
    comp = [comparison_html(tables[k], latest, parts) for k in COMPARE_TABLES if k in tables]
    comp = [c for c in comp if c]
    pub = [published_table_html(tables[k]) for k in COMPARE_TABLES if k in tables]
    return (leaderboard_sections(subs, prefix)
            + '<h2>Beside the paper <span class="badge published">published rows, not re-run here</span></h2>'
            + ("\n".join(comp) if comp else "<p>No computed dataset shares categories with the paper's tables; "
               "the published tables follow.</p>" + "\n".join(pub))
            + f'<p>All published tables: <a href="{prefix}published.html">published.html</a>.</p>')


def published_page() -> str:
    tables = load_tables()
    toc = "".join(f'<li><a href="#{esc(t.key)}">{esc(t.title)}</a></li>' for t in tables)
    body = ("<p>The PD²GS paper's tables, transcribed exactly from pd2gs.tex (label and line numbers given "
            "with each). These are <strong>published numbers, not re-run here</strong>; they are never mixed "
            f"into the computed rankings.</p><ul>{toc}</ul>" + "\n".join(published_table_html(t) for t in tables))
    return page("Published results (PD²GS paper)", body)


def build_site(engine: Engine, out: str | Path, *, plots: bool = True) -> Path:
    """Write the whole site to ``out`` atomically (replacing an existing site folder)."""
    subs = list_submissions(engine)
    out = Path(out)
    with atomic_dir(out, overwrite=True) as tmp:
        (tmp / "index.html").write_text(page("rsart leaderboard", index_body(engine, subs)), encoding="utf-8")
        (tmp / "published.html").write_text(published_page(), encoding="utf-8")
        (tmp / "metrics.html").write_text(metrics_page(), encoding="utf-8")
        (tmp / "methods.html").write_text(page("Methods", method_pages(subs, tmp, plots, previous=out if out.is_dir() else None)), encoding="utf-8")
        (tmp / "leaderboard.md").write_text(leaderboard_markdown(subs), encoding="utf-8")
        (tmp / "leaderboard.csv").write_text(leaderboard_csv(subs, by_category=False), encoding="utf-8")
        (tmp / "leaderboard_by_category.csv").write_text(leaderboard_csv(subs, by_category=True), encoding="utf-8")
        (tmp / "published.csv").write_text(published_csv(), encoding="utf-8")
        files = ["leaderboard.md", "leaderboard.csv", "leaderboard_by_category.csv", "published.csv"]
        (tmp / "downloads.html").write_text(
            page("Downloads", "<ul>" + "".join(f'<li><a href="{f}">{f}</a></li>' for f in files) + "</ul>"),
            encoding="utf-8")
    return out
