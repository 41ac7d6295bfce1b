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
from .site import (COMPARE_TABLES, _method_label, best_per_method, best_value, comparison_html, group_subs,
                   leaderboard_sections, method_pages, metrics_page, part_index_means, pen_value,
                   published_table_html, rank_subs)
from .store import SubmissionRow, list_submissions
from .tracks import Track


def _fmt(s: SubmissionRow, key: str, best: float | None) -> str:
    """The penalised mean (bold when it is the column's best), the paper-convention mean in brackets."""
    info = INFO[key]
    got = s.agg.get(S.MEAN, {}).get(key)
    if got is None:
        return "·"
    val, _n, nf = got
    pv = pen_value(s, S.MEAN, key)
    scale = 100 if info.percent else 1
    paper = "*" if (val is None and nf) else ("–" if val is None else f"{val * scale:.3f}{'*' if nf else ''}")
    if pv is None:
        return paper if paper == "–" else f"? ({paper})"
    text = f"{pv * scale:.3f}"
    return (f"**{text}**" if best is not None and pv == best else text) + f" ({paper})"


def leaderboard_markdown(subs: list[SubmissionRow], all_runs: bool = False) -> str:
    metrics = present_metrics(subs) if subs else []
    out = ["# rsart leaderboard (computed here)", "",
           "Mean over categories. Each cell: the **penalised mean** (a failed object counts the metric's worst "
           "value; docs/evaluation.md §4.1), the column's best in bold, then in brackets the paper-convention "
           "mean (failures left out; `*` = failed on ≥1 object or part; `–` = not applicable). Rows are ranked "
           "by the mean rank over the metrics' penalised means; "
           + ("every run is listed." if all_runs else "one row per method: its best-ranked run.")
           + " Published paper rows are in published.csv and are not re-run here.", ""]
    for ds, tracks in group_subs(subs, all_runs=all_runs).items():
        out += [f"## {ds}", ""]
        for _tk, ss in tracks.items():
            best = {k: best_value(ss, S.MEAN, k) for k in metrics}
            out += [f"### {Track(**ss[0].track).label()}", "",
                    "| Rank | Method | Run | Config | Team | Objects | Completion | "
                    + " | ".join(INFO[k].label for k in metrics) + " |",
                    "|---:|---|---|---|---|---:|---:|" + "---:|" * len(metrics)]
            for i, (_score, s) in enumerate(rank_subs(ss, S.MEAN, metrics)):
                cells = [_fmt(s, k, best[k]) for k in metrics]
                comp = "?" if s.completion is None else f"{100 * s.completion:.0f} %"
                out.append(f"| {i + 1} | {_method_label(s).replace('|', '/')} | {s.run.replace('|', '/')} | "
                           f"`{(s.run_config_hash or '')[:8]}` | {(s.team or '').replace('|', '/')} | "
                           f"{s.n_objects} ({s.n_failed_objects} failed) | {comp} | " + " | ".join(cells) + " |")
            out.append("")
    return "\n".join(out) + "\n"


def leaderboard_csv(subs: list[SubmissionRow], by_category: bool) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["submission_id", "method", "version", "team", "dataset", "dataset_version", "split", "camera_poses",
                "states", "part_count", "inputs", "toolkit_version", "config_hash", "category", "metric", "value",
                "n", "n_failed", "submitted_utc", "penalised", "completion", "run_label", "run_config_hash",
                "objects_completion"])
    for s in subs:
        for cat, ms in sorted(s.agg.items()):
            if (cat == S.MEAN) == by_category:
                continue
            for m, (v, n, nf) in sorted(ms.items()):
                pv, comp = s.pen.get(cat, {}).get(m, (None, None))
                w.writerow([s.id, s.method_name, s.method_version, s.team or "", s.dataset_name, s.dataset_version,
                            s.split, s.track["camera_poses"], s.track["states"], s.track["part_count"],
                            s.track["inputs"], s.toolkit_version, s.config_hash, "Mean" if cat == S.MEAN else cat, m,
                            "" if v is None else repr(v), n, nf,
                            time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(s.created_at)),
                            "" if pv is None else repr(pv), "" if comp is None else repr(comp), s.run_label or "",
                            s.run_config_hash or "", "" if s.completion is None else repr(s.completion)])
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


def index_body(engine: Engine, subs: list[SubmissionRow], prefix: str = "", all_runs: bool = False) -> str:
    tables = {t.key: t for t in load_tables()}
    best = best_per_method(subs)
    parts = part_index_means(engine, [s.id for s in best])
    comp = [comparison_html(tables[k], best, parts) for k in COMPARE_TABLES if k in tables]
    comp = [c for c in comp if c]
    pub = [published_table_html(tables[k]) for k in COMPARE_TABLES if k in tables]
    return (leaderboard_sections(subs, prefix, all_runs=all_runs)
            + '<h2>Beside the paper <span class="badge published">published rows, not re-run here</span></h2>'
            + ("\n".join(comp) if comp else "<p>Computed rows go beside the paper's rows only when they were "
               "scored on the same objects in the same units. No computed submission was (the paper does not "
               "list its object ids), so the published tables follow on their own.</p>" + "\n".join(pub))
            + f'<p>All published tables: <a href="{prefix}published.html">published.html</a>.</p>')


def published_page() -> str:
    tables = load_tables()
    toc = "".join(f'<li><a href="#{esc(t.key)}">{esc(t.title)}</a></li>' for t in tables)
    body = ("<p>The PD²GS paper's tables, transcribed exactly from pd2gs.tex (label and line numbers given "
            "with each). These are <strong>published numbers, not re-run here</strong>; they are never mixed "
            f"into the computed rankings.</p><ul>{toc}</ul>" + "\n".join(published_table_html(t) for t in tables))
    return page("Published results (PD²GS paper)", body)


def build_site(engine: Engine, out: str | Path, *, plots: bool = True, all_runs: bool = False) -> Path:
    """Write the whole site to ``out`` atomically (replacing an existing site folder); ``all_runs`` lists
    every run of each method in the rankings (default: each method's best-ranked run)."""
    subs = list_submissions(engine)
    out = Path(out)
    with atomic_dir(out, overwrite=True) as tmp:
        (tmp / "index.html").write_text(page("rsart leaderboard", index_body(engine, subs, all_runs=all_runs)), encoding="utf-8")
        (tmp / "published.html").write_text(published_page(), encoding="utf-8")
        (tmp / "metrics.html").write_text(metrics_page(), encoding="utf-8")
        (tmp / "methods.html").write_text(page("Methods", method_pages(subs, tmp, plots, previous=out if out.is_dir() else None)), encoding="utf-8")
        (tmp / "leaderboard.md").write_text(leaderboard_markdown(subs, all_runs), encoding="utf-8")
        (tmp / "leaderboard.csv").write_text(leaderboard_csv(subs, by_category=False), encoding="utf-8")
        (tmp / "leaderboard_by_category.csv").write_text(leaderboard_csv(subs, by_category=True), encoding="utf-8")
        (tmp / "published.csv").write_text(published_csv(), encoding="utf-8")
        files = ["leaderboard.md", "leaderboard.csv", "leaderboard_by_category.csv", "published.csv"]
        (tmp / "downloads.html").write_text(
            page("Downloads", "<ul>" + "".join(f'<li><a href="{f}">{f}</a></li>' for f in files) + "</ul>"),
            encoding="utf-8")
    return out
