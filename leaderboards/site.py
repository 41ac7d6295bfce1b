"""``rsart leaderboard build``: the static site (HTML, Markdown, CSV) from the result store.

Pages: ``index.html`` (per dataset and track: a sortable table of the Mean over categories, a sortable
table per category, and the paper-style table with ``*`` failure marks; then the paper's layout with our
computed rows beside the published ones), ``published.html`` (every transcribed table of the PD²GS
paper, marked as published and not re-run here), ``metrics.html``, ``methods.html`` and one page per
method with per-category plots, ``downloads.html``; exports ``leaderboard.md``, ``leaderboard.csv``,
``leaderboard_by_category.csv`` and ``published.csv``. Published rows never enter a computed ranking.
"""
from __future__ import annotations

import io
import time
from collections import defaultdict
from pathlib import Path

from sqlalchemy import and_, func, select
from sqlalchemy.engine import Engine

from . import schema as S
from .html import CORE, INFO, Cell, agg_cell, esc, header, metric_cell, page, present_metrics, slug, table
from .paper import PAPER_METHOD_INPUTS, PaperTable
from .store import SubmissionRow
from .tracks import Track

#: Paper column → our category ids (case-insensitive aliases).
CATEGORY_ALIASES = {
    "box": ["box"], "door": ["door"], "eyeglasses": ["eyeglasses", "eyeglasses_rs"], "faucet": ["faucet"],
    "oven": ["oven"], "fridge": ["refrigerator", "fridge"], "storage": ["storage", "storagefurniture"],
    "table": ["table"], "drawers": ["drawer", "drawers"], "desk lamps": ["desk_lamp", "desklamp", "lamp"],
    "floppy-disk drives": ["floppy_drive", "floppy"], "woven baskets": ["woven_basket", "basket"],
    "phone/laptop stand": ["stand", "phone_stand", "laptop_stand"],
}
#: Paper row group → (our metric, movable part index or None for object level).
PAPER_GROUPS = {"CD-s": ("cd_s", None), "CD-w": ("cd_w", None)}
for _i in range(3):
    PAPER_GROUPS.update({f"Axis Ang {_i}": ("axis_ang", _i), f"Axis Pos {_i}": ("axis_pos", _i),
                         f"Part Motion {_i}": ("part_motion", _i), f"CD-m {_i}": ("cd_m", _i)})
COMPARE_TABLES = ("partnet_main", "rsart_main")
#: Metrics drawn in the per-method plots.
PLOT_METRICS = ("cd_s", "cd_m", "cd_w", "axis_ang", "axis_pos", "part_motion_rev")


def _date(t: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M", time.gmtime(t))


def _method_label(s: SubmissionRow) -> str:
    return f"{s.method_name} {s.method_version}".strip()


def group_subs(subs: list[SubmissionRow], latest_only: bool = False) -> dict[str, dict[str, list[SubmissionRow]]]:
    """dataset label → track key → submissions (insertion order); with ``latest_only`` one row per method
    (its newest submission in that dataset and track; every submission stays on the method's page)."""
    out: dict[str, dict[str, list[SubmissionRow]]] = {}
    for s in subs:
        out.setdefault(s.dataset_label, {}).setdefault(Track(**s.track).key(), []).append(s)
    if latest_only:
        for tracks in out.values():
            for k, ss in tracks.items():
                newest: dict[str, SubmissionRow] = {}
                for s in ss:
                    if s.method_name not in newest or s.created_at >= newest[s.method_name].created_at:
                        newest[s.method_name] = s
                tracks[k] = [s for s in ss if newest[s.method_name] is s]
    return out


def latest_per_method(subs: list[SubmissionRow]) -> list[SubmissionRow]:
    """Newest submission of each method in each dataset and track."""
    return [s for tracks in group_subs(subs, latest_only=True).values() for ss in tracks.values() for s in ss]


def _row_head(s: SubmissionRow, prefix: str) -> list[Cell]:
    name = Cell(_method_label(s), s.method_name.lower())
    return [name, Cell(s.team or "", (s.team or "").lower()),
            Cell(f"{s.n_objects} ({s.n_failed_objects} failed)", s.n_failed_objects, "n"),
            Cell(_date(s.created_at), s.created_at)]


def ranking_table(subs: list[SubmissionRow], category: str, metrics: list[str], table_id: str = "") -> str:
    heads = ["Method", "Team", "Objects", "Submitted"] + [header(INFO[k]) for k in metrics]
    rows = [_row_head(s, "") + [agg_cell(s.agg, category, k) for k in metrics] for s in subs]
    return table(heads, rows, table_id=table_id)


def paper_style_table(subs: list[SubmissionRow], metrics: list[str]) -> str:
    """Metric groups as rows (one line per submission), categories as columns, a Mean column, ``*`` marks."""
    cats = sorted({c for s in subs for c in s.agg if c != S.MEAN})
    heads = ["Metric", "Method"] + cats + ["Mean"]
    rows = []
    for k in metrics:
        if not any(s.agg.get(c, {}).get(k, (None, 0, 0))[1] or s.agg.get(c, {}).get(k, (None, 0, 0))[2]
                   for s in subs for c in cats):
            continue
        for s in subs:
            rows.append([Cell(header(INFO[k])), Cell(_method_label(s))]
                        + [agg_cell(s.agg, c, k) for c in cats] + [agg_cell(s.agg, S.MEAN, k)])
    return table(heads, rows, sortable=False)


def leaderboard_sections(subs: list[SubmissionRow], prefix: str = "") -> str:
    """The computed part of index.html (also the live page's body)."""
    if not subs:
        return "<p>No scored submissions yet.</p>"
    metrics = present_metrics(subs)
    parts = ['<p class="note">One row per method and track: its newest submission (all submissions are on the '
             f'<a href="{prefix}methods.html">method pages</a>).</p>']
    for ds, tracks in group_subs(subs, latest_only=True).items():
        parts.append(f'<h2>{esc(ds)} <span class="badge computed">computed here</span></h2>')
        for tk, ss in tracks.items():
            tr = Track(**ss[0].track)
            parts.append(f"<h3>Track: {esc(tr.label())}</h3>")
            parts.append(f"<h4>Mean over categories</h4>"
                         + ranking_table(ss, S.MEAN, metrics, table_id=f"rank-{slug(ds)}-{tk}"))
            parts.append("<details><summary>Paper-style table (categories as columns, <code>*</code> = failed on "
                         "≥1 object or part)</summary>" + paper_style_table(ss, metrics) + "</details>")
            for c in sorted({c for s in ss for c in s.agg if c != S.MEAN}):
                parts.append(f"<details><summary>Category: {esc(c)}</summary>" + ranking_table(ss, c, metrics)
                             + "</details>")
    return "\n".join(parts)


# ----------------------------------------------------------------------------- published rows
def published_table_html(t: PaperTable) -> str:
    heads = ([t.group_kind.capitalize()] if any(r.group for r in t.rows) else []) + ["Method"] + list(t.columns)
    rows = []
    for r in t.rows:
        name = r.display + (" (RGB-D input)" if PAPER_METHOD_INPUTS.get(r.method) == "rgbd" else "")
        cells = ([Cell(r.group or "")] if any(x.group for x in t.rows) else []) + [Cell(name)]
        for c in r.cells:
            title = "failed on ≥1 object" if c.failed else ("" if c.applicable else "not applicable")
            cells.append(Cell(c.text, c.value, "n fail" if c.failed else "n", title))
        rows.append(cells)
    return (f'<h3 id="{esc(t.key)}">{esc(t.title)} <span class="badge published">published, not re-run here</span></h3>'
            f'<p class="note">Dataset: {esc(t.dataset)}. Source: {esc(t.cite())}. Numbers transcribed exactly; '
            f'<code>*</code> and <code>F</code> are the paper\'s failure marks.</p>'
            + table(heads, rows, sortable=False, row_classes=["pub"] * len(rows)))


def _our_cats(cats_present: set[str], column: str) -> list[str]:
    aliases = CATEGORY_ALIASES.get(column.lower(), [column.lower()])
    return [c for c in cats_present if c.lower() in aliases]


def part_index_means(engine: Engine, ids: list[int]) -> dict[int, dict[str, dict[tuple[str, int], tuple]]]:
    """sid → category → (metric, movable index) → (mean|None, n, n_failed) over objects, from ``scores``."""
    if not ids:
        return {}
    sc = S.scores
    q = (select(sc.c.submission_id, sc.c.category, sc.c.metric, sc.c.part_index, func.avg(sc.c.value),
                func.count(sc.c.value), func.sum(sc.c.failed.cast(S.Integer)))
         .where(and_(sc.c.submission_id.in_(ids), sc.c.part_index.is_not(None),
                     sc.c.metric.in_(["axis_ang", "axis_pos", "part_motion", "cd_m"]),
                     sc.c.state.in_(["", "mean"])))
         .group_by(sc.c.submission_id, sc.c.category, sc.c.metric, sc.c.part_index))
    out: dict = defaultdict(lambda: defaultdict(dict))
    with engine.connect() as conn:
        for sid, cat, m, pi, avg, n, nf in conn.execute(q):
            out[sid][cat][(m, int(pi))] = (None if avg is None else float(avg), int(n), int(nf or 0))
    return out


def comparison_html(t: PaperTable, subs: list[SubmissionRow], parts: dict) -> str:
    """The paper's table layout: published rows (marked) with our computed rows beside them per metric."""
    mine = [s for s in subs if any(_our_cats(set(s.agg), col) for col in t.columns if col != "Mean")]
    if not mine:
        return ""
    heads = ["Metric", "Method", "Kind"] + list(t.columns)
    rows, classes = [], []
    for g in t.groups():
        for r in t.rows:
            if r.group != g:
                continue
            rows.append([Cell(g or ""), Cell(r.display), Cell("published")]
                        + [Cell(c.text, c.value, "n fail" if c.failed else "n") for c in r.cells])
            classes.append("pub")
        metric, idx = PAPER_GROUPS.get(g or "", (None, None))
        if metric is None:
            continue
        for s in mine:
            cells, vals = [], []
            for col in t.columns:
                if col == "Mean":
                    continue
                ours = _our_cats(set(s.agg), col)
                if not ours:
                    cells.append(Cell("·", None, "n", "category not in this dataset"))
                    continue
                if idx is None:
                    v, n, nf = s.agg[ours[0]].get(metric, (None, 0, 0))
                else:
                    v, n, nf = parts.get(s.id, {}).get(ours[0], {}).get((metric, idx), (None, 0, 0))
                info = INFO["part_motion_rev" if metric == "part_motion" else metric]
                cells.append(metric_cell(info, v, nf, n))
                if v is not None:
                    vals.append(v)
            mean = sum(vals) / len(vals) if vals else None
            cells.append(Cell("·" if mean is None else f"{mean:.3f}", mean, "n", "mean over the paper's columns present"))
            rows.append([Cell(g or ""), Cell(_method_label(s)), Cell(f"computed ({s.dataset_label})")] + cells)
            classes.append("")
    return (f'<h3>{esc(t.title)}: paper layout, published rows beside ours</h3>'
            f'<p class="note">Italic rows: <span class="badge published">published</span> in the PD²GS paper '
            f'({esc(t.cite())}), not re-run here. Other rows: <span class="badge computed">computed here</span> on '
            f'our datasets (categories matched by name; Part Motion in ° for revolute, scene units for prismatic '
            f'parts). Our rows come from our own datasets (other objects, often in metres, not in the scene units '
            f'of the paper), so they show the protocol at work, not a re-run of the paper. Published and computed rows are '
            f'never ranked together.</p>'
            + table(heads, rows, sortable=False, row_classes=classes))


# ----------------------------------------------------------------------------- other pages
METRIC_TEXT = {
    "cd_s": "Chamfer distance of the static part: 10k area samples per mesh, squared L2, mean each way, summed, ×1000, mean of 3 seeds, start and end states averaged.",
    "cd_m": "Chamfer distance of each movable part (matched), averaged over the object's movable parts.",
    "cd_w": "Chamfer distance of the whole object (given mesh, or union of the parts).",
    "axis_ang": "Angle between predicted and true axis lines, 0–90°, sign-invariant.",
    "axis_pos": "Distance between the axis lines ×10 (revolute joints only; '–' for prismatic).",
    "part_motion_rev": "Geodesic angle between predicted and true start→end rotations (revolute parts).",
    "part_motion_pri": "‖Δv_pred·a_pred − Δv·a‖ in scene units (prismatic parts).",
    "type_acc": "Matched true parts whose predicted joint type is right.",
    "count_acc": "Objects whose number of predicted movable parts is right.",
}


def metrics_page() -> str:
    from rsart.evaluation.report import METRICS

    rows = [[Cell(m.label), Cell(m.unit), Cell("higher" if m.higher_better else "lower"), Cell(m.group),
             Cell(METRIC_TEXT.get(m.key, "Image/mask metric (when renders or masks are submitted)."))] for m in METRICS]
    body = (table(["Metric", "Unit", "Better", "Group", "Definition"], rows, sortable=False)
            + "<p>Failures are counted and marked <code>*</code>; they never enter a mean as numbers. Category "
              "values are means over the category's objects; the Mean column is the mean over categories. Full "
              "definitions: docs/evaluation.md. Tracks: camera poses (gt/estimated), states used (2/N), part "
              "count (given/inferred), inputs (RGB/RGB-D), read from the submission's <code>method</code> block.</p>")
    return page("Metric definitions", body)


def method_plot(s: SubmissionRow, metrics: list[str]) -> bytes:
    """Per-category bars for each metric of one submission (PNG bytes); failed cells hatched."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cats = sorted(c for c in s.agg if c != S.MEAN)
    keys = [k for k in PLOT_METRICS if k in metrics
            and any(s.agg[c].get(k, (None, 0, 0))[0] is not None for c in cats)] or metrics[:1]
    ncol = min(3, len(keys))
    nrow = (len(keys) + ncol - 1) // ncol
    # fixed margins instead of tight_layout: matplotlib's layout pass dominated the site build time
    fig, axes = plt.subplots(nrow, ncol, figsize=(4 * ncol, 2.8 * nrow), squeeze=False)
    fig.subplots_adjust(left=0.06, right=0.98, top=0.9, bottom=0.28, hspace=0.9, wspace=0.25)
    for ax, k in zip(axes.flat, keys):
        info = INFO[k]
        vals = [s.agg[c].get(k, (None, 0, 0)) for c in cats]
        ys = [(v[0] or 0.0) * (100 if info.percent else 1) for v in vals]
        bars = ax.bar(range(len(cats)), ys, color="#4a7db5")
        for b, v in zip(bars, vals):
            if v[2]:
                b.set_hatch("//")
                b.set_edgecolor("#a00")
        ax.set_xticks(range(len(cats)), cats, rotation=45, ha="right", fontsize=7)
        ax.set_title(header(info), fontsize=9)
    for ax in list(axes.flat)[len(keys):]:
        ax.axis("off")
    fig.suptitle(f"{_method_label(s)} on {s.dataset_label}", fontsize=10)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=72)
    plt.close(fig)
    return buf.getvalue()


def method_pages(subs: list[SubmissionRow], out: Path, plots: bool = True, previous: Path | None = None) -> str:
    """Write ``out/methods/*.html`` (+ PNGs) → the methods index body. A plot is named after its submission
    id, so an unchanged one is copied from the ``previous`` site instead of being drawn again."""
    by: dict[str, list[SubmissionRow]] = {}
    for s in subs:
        by.setdefault(s.method_name, []).append(s)
    (out / "methods").mkdir(exist_ok=True)
    index_rows = []
    metrics = present_metrics(subs) if subs else CORE
    for name, ss in sorted(by.items(), key=lambda kv: kv[0].lower()):
        sl = _slug_of(name)
        body = [f"<p>{len(ss)} submission(s). Published rows for this method (if any) are on "
                f'<a href="../published.html">the published page</a>.</p>']
        latest: dict[str, SubmissionRow] = {}
        for s in ss:
            latest[s.dataset_label] = s
        for ds, s in latest.items():
            body.append(f"<h2>{esc(ds)} (latest: {esc(_method_label(s))}, {_date(s.created_at)})</h2>")
            body.append(paper_style_table([s], metrics))
            if plots:
                png = f"{sl}-{slug(ds)}-s{s.id}.png"
                old = previous / "methods" / png if previous is not None else None
                if old is not None and old.is_file() and not old.is_symlink():
                    (out / "methods" / png).write_bytes(old.read_bytes())
                else:
                    (out / "methods" / png).write_bytes(method_plot(s, metrics))
                body.append(f'<img src="{esc(png)}" alt="per-category plot of {esc(name)} on {esc(ds)}">')
        body.append("<h2>All submissions</h2>" + ranking_table(ss, S.MEAN, metrics))
        (out / "methods" / f"{sl}.html").write_text(page(f"Method: {name}", "\n".join(body), prefix="../"),
                                                    encoding="utf-8")
        index_rows.append([Cell(name, name.lower()), Cell(str(len(ss)), len(ss), "n")])
    links = "".join(f'<li><a href="methods/{esc(_slug_of(n))}.html">{esc(n)}</a></li>'
                    for n in sorted(by, key=str.lower))
    return f"<ul>{links}</ul>" + table(["Method", "Submissions"], index_rows)


def _slug_of(name: str) -> str:
    """Page name of a method: its slug, plus a short hash when the slug is not the name itself (unique)."""
    import hashlib

    s = slug(name)
    return s if s == name.lower() else f"{s}-{hashlib.sha256(name.encode()).hexdigest()[:8]}"
