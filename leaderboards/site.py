"""``rsart leaderboard build``: the static site (HTML, Markdown, CSV) from the result store.

Pages: ``index.html`` (per dataset and track: the runs ranked by the penalised Mean over categories with
their completion rate, run label and config hash, best value per column highlighted; a ranked table per
category; the paper-style table with ``*`` failure marks; then the paper's layout, with our computed rows
beside the published ones only for submissions scored on the paper's objects in its units), ``published.html`` (every transcribed table of the PD²GS
paper, marked as published and not re-run here), ``metrics.html``, ``methods.html`` and one page per
method with per-category plots, ``downloads.html``; exports ``leaderboard.md``, ``leaderboard.csv``,
``leaderboard_by_category.csv`` and ``published.csv``. Published rows never enter a computed ranking.
"""
from __future__ import annotations

import io
import time
from collections import defaultdict
from dataclasses import dataclass
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


def pen_value(s: SubmissionRow, category: str, key: str) -> float | None:
    """The submission's penalised mean of ``key`` in ``category`` (None if not applicable or unknown)."""
    return s.pen.get(category, {}).get(key, (None, None))[0]


def rank_subs(subs: list[SubmissionRow], category: str, metrics: list[str]) -> list[tuple[float | None, SubmissionRow]]:
    """(mean rank, submission), best first. Per metric, rows are ranked by their **penalised** mean (failures at
    the metric's worst value, docs/evaluation.md §4.1; ties share the mean of their positions; a row with no
    value ranks last); a row's score is its mean rank over the metrics that any row has. Ties: higher
    completion first, then the older submission."""
    n = len(subs)
    ranks: dict[int, list[float]] = {s.id: [] for s in subs}
    for k in metrics:
        vals = {s.id: pen_value(s, category, k) for s in subs}
        have = sorted((v for v in vals.values() if v is not None), reverse=INFO[k].higher_better)
        if not have:
            continue
        for sid, v in vals.items():
            if v is None:
                ranks[sid].append(float(n))
            else:
                pos = [i + 1 for i, x in enumerate(have) if x == v]
                ranks[sid].append(sum(pos) / len(pos))
    score = {sid: (sum(r) / len(r) if r else None) for sid, r in ranks.items()}
    order = sorted(subs, key=lambda s: (score[s.id] is None, score[s.id] or 0.0, -(s.completion or 0.0), s.created_at))
    return [(score[s.id], s) for s in order]


def group_subs(subs: list[SubmissionRow], all_runs: bool = True) -> dict[str, dict[str, list[SubmissionRow]]]:
    """dataset label → track key → submissions, ranked (:func:`rank_subs` on the Mean over categories);
    without ``all_runs`` one row per method: its best-ranked run in that dataset and track (every run
    stays on the method's page)."""
    out: dict[str, dict[str, list[SubmissionRow]]] = {}
    for s in subs:
        out.setdefault(s.dataset_label, {}).setdefault(Track(**s.track).key(), []).append(s)
    for tracks in out.values():
        for k, ss in tracks.items():
            ranked = [s for _r, s in rank_subs(ss, S.MEAN, present_metrics(ss))]
            if not all_runs:
                seen: set[str] = set()
                ranked = [s for s in ranked if not (s.method_name in seen or seen.add(s.method_name))]
            tracks[k] = ranked
    return out


def best_per_method(subs: list[SubmissionRow]) -> list[SubmissionRow]:
    """Best-ranked run of each method in each dataset and track."""
    return [s for tracks in group_subs(subs, all_runs=False).values() for ss in tracks.values() for s in ss]


def _row_head(s: SubmissionRow) -> list[Cell]:
    cfg = s.run_config_hash or ""
    return [Cell(_method_label(s), s.method_name.lower()),
            Cell(s.run, s.run.lower(), "", f"submission {s.id}"),
            Cell(cfg[:8], cfg, "", f"method settings hash {cfg}; eval config hash {s.config_hash}"),
            Cell(s.team or "", (s.team or "").lower()),
            Cell(f"{s.n_objects} ({s.n_failed_objects} failed)", s.n_failed_objects, "n"),
            Cell("?" if s.completion is None else f"{100 * s.completion:.0f} %", s.completion, "n",
                 "objects that are not null"),
            Cell(_date(s.created_at), s.created_at)]


def pen_cell(s: SubmissionRow, category: str, key: str, best: float | None) -> Cell:
    """The penalised mean, the paper-convention mean and the completion in its tooltip; ``best`` class when
    it equals the column's best value."""
    info = INFO[key]
    got = s.agg.get(category, {}).get(key)
    if got is None:
        return Cell("·", None, "n", "not evaluated")
    v, n, nf = got
    pv, comp = s.pen.get(category, {}).get(key, (None, None))
    paper = metric_cell(info, v, nf, n).text
    if pv is None:
        if not n and not nf:
            return Cell("–", None, "n", "not applicable")
        return Cell("?", None, "n", f"no penalised mean recorded (paper convention {paper})")
    scale = 100 if info.percent else 1
    fmt = ".1f" if info.percent or key == "psnr" else ".3f"
    tip = (f"penalised mean (failures at the worst value); paper convention {paper}"
           + ("" if comp is None else f"; completion {100 * comp:.0f} %"))
    cls = "n" + (" best" if best is not None and pv == best else "") + (" fail" if nf else "")
    return Cell(f"{pv * scale:{fmt}}", pv * scale, cls, tip)


def best_value(subs: list[SubmissionRow], category: str, key: str) -> float | None:
    """The best penalised mean of ``key`` in ``category`` among ``subs`` (the highlighted value; None if none)."""
    vals = [v for v in (pen_value(s, category, key) for s in subs) if v is not None]
    if not vals:
        return None
    return max(vals) if INFO[key].higher_better else min(vals)


def ranking_table(subs: list[SubmissionRow], category: str, metrics: list[str], table_id: str = "") -> str:
    """Ranked rows (:func:`rank_subs`): rank, method, run label, config hash, completion, then the penalised
    mean of every metric, the best value of each column highlighted."""
    units = {s.units for s in subs}
    u = next(iter(units)) if len(units) == 1 else None  # "m" when every row was scored in metres
    heads = ["Rank", "Method", "Run", "Config", "Team", "Objects", "Completion", "Submitted"] + [
        header(INFO[k], u) for k in metrics]
    best = {k: best_value(subs, category, k) for k in metrics}
    rows = []
    for i, (score, s) in enumerate(rank_subs(subs, category, metrics)):
        rank = Cell(str(i + 1), i + 1, "n", "" if score is None else f"mean rank over the metrics {score:.2f}")
        rows.append([rank] + _row_head(s) + [pen_cell(s, category, k, best[k]) for k in metrics])
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


def leaderboard_sections(subs: list[SubmissionRow], prefix: str = "", all_runs: bool = False) -> str:
    """The computed part of index.html (also the live page's body); ``all_runs``: every run of each method,
    not only its best one."""
    if not subs:
        return "<p>No scored submissions yet.</p>"
    metrics = present_metrics(subs)
    rows = ("One row per run (submission)." if all_runs else
            "One row per method and track: its best-ranked run (every run is on the "
            f'<a href="{prefix}methods.html">method pages</a>; <code>rsart leaderboard build --all-runs</code> '
            "lists them all here).")
    parts = [f'<p class="note">{rows} Rows are ranked by the <strong>penalised mean</strong>: per metric, a '
             "failed object counts the metric's worst value (0 %, 90° Axis Ang, size-derived caps; "
             f'<a href="{prefix}metrics.html">metrics</a>), so skipping hard objects never helps; the rank is '
             "the mean rank over the metrics. Completion = objects not null. The best value of each column is "
             "highlighted; the tooltip of a cell gives the paper-convention mean (failures left out, "
             "<code>*</code>) and the metric's completion.</p>"]
    for ds, tracks in group_subs(subs, all_runs=all_runs).items():
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


@dataclass(frozen=True)
class PaperEvalSet:
    """What a published table was computed on: ``units`` ("m", or "" for unitless scene units) and the
    ``objects`` (dataset object ids; None when the paper does not list them)."""

    units: str
    objects: frozenset[str] | None


#: The objects and units of the compared paper tables. The PD²GS paper lists neither its PartNet-Mobility
#: instances ("two to three instances per category", scene units) nor the ids of RS-Art's 18 objects (metres),
#: so until they are known no computed row is put beside these published rows.
PAPER_EVAL_SETS = {"partnet_main": PaperEvalSet("", None), "rsart_main": PaperEvalSet("m", None)}


def same_eval_set(s: SubmissionRow, es: PaperEvalSet | None) -> bool:
    """True when ``s`` was scored on exactly the table's objects, in its units."""
    return (es is not None and es.objects is not None and s.units is not None and s.units == es.units
            and s.objects == es.objects)


def comparison_html(t: PaperTable, subs: list[SubmissionRow], parts: dict,
                    eval_set: PaperEvalSet | None = None) -> str:
    """The paper's table layout: published rows (marked) with our computed rows beside them per metric, for
    the submissions scored on the same objects in the same units as the table (``eval_set``, default
    :data:`PAPER_EVAL_SETS`); "" when there is none."""
    es = eval_set if eval_set is not None else PAPER_EVAL_SETS.get(t.key)
    mine = [s for s in subs if same_eval_set(s, es)
            and any(_our_cats(set(s.agg), col) for col in t.columns if col != "Mean")]
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
            f'the same objects, in the same units (categories matched by name; Part Motion in ° for revolute, '
            f'scene units for prismatic parts). Published and computed rows are never ranked together.</p>'
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
            + "<p>Failures are counted and marked <code>*</code>; they never enter the paper-convention mean as "
              "numbers. Category values are means over the category's objects; the Mean column is the mean over "
              "categories. The rankings use the <strong>penalised mean</strong> instead, in which a failure counts "
              "the metric's worst value: 0 % for accuracies, 0 dB / 0 for PSNR / SSIM, 90° Axis Ang, 180° "
              "revolute Part Motion, and for Axis Pos 10·d, prismatic Part Motion d and every Chamfer 2000·d², "
              "with d the object's bounding-box diagonal; scored values are clipped to the same caps. Completion = "
              "objects scored without failure. Full definitions: docs/evaluation.md §4.1. Tracks: camera poses (gt/estimated), states used (2/N), part "
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
        xs = [i for i, v in enumerate(vals) if v[0] is not None]  # no 0-height bar for a missing value
        bars = ax.bar(xs, [vals[i][0] * (100 if info.percent else 1) for i in xs], color="#4a7db5")
        for b, i in zip(bars, xs):
            if vals[i][2]:
                b.set_hatch("//")
                b.set_edgecolor("#a00")
        for i, v in enumerate(vals):
            if v[0] is None:
                ax.text(i, 0, "failed" if v[2] else "n/a", rotation=90, ha="center", va="bottom", fontsize=7,
                        color="#a00" if v[2] else "#777")
        ax.set_xlim(-0.6, len(cats) - 0.4)
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
