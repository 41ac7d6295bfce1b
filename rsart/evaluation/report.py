"""Aggregation and reports: scores.json, per-part/per-object CSVs, summary.md, summary.png.

Aggregation rules (docs/evaluation.md):

* object value of a per-part metric = mean over the object's movable parts that scored it;
* category value = mean over its objects that scored the metric; ``n_failed`` counts objects where the
  metric failed for the object or for any of its parts (then the table cell carries ``*``);
* Mean column = mean of the category values (every category weighs the same, as in the papers' tables);
  ``overall.objects`` also gives the plain mean over objects;
* failures never enter the paper-convention mean as numbers; not-applicable metrics (Axis Pos of prismatic
  joints, image metrics without submitted images) are neither values nor failures and show as "–";
* beside it, a **penalised mean** (``penalised_mean``) in which a failure counts as the metric's worst value
  (:func:`penalty_cap`) and scored values are clipped to that value, so giving up never scores better than
  trying; and a **completion rate** (``completion``): objects that scored the metric without any failure /
  objects where it applies.
"""
from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..io import atomic_write_bytes, atomic_write_text, write_json
from .score import IMAGE_METRICS, OBJECT_METRICS, PART_METRICS


@dataclass(frozen=True)
class MetricInfo:
    key: str
    label: str
    unit: str
    group: str
    percent: bool = False
    higher_better: bool = False


METRICS = [
    MetricInfo("cd_s", "CD-s", "×1000 units²", "Geometry: Chamfer (×1000) ↓"),
    MetricInfo("cd_m", "CD-m", "×1000 units²", "Geometry: Chamfer (×1000) ↓"),
    MetricInfo("cd_w", "CD-w", "×1000 units²", "Geometry: Chamfer (×1000) ↓"),
    MetricInfo("axis_ang", "Axis Ang", "°", "Joints ↓"),
    MetricInfo("axis_pos", "Axis Pos", "×10 units", "Joints ↓"),
    MetricInfo("part_motion_rev", "Part Motion (revolute)", "°", "Joints ↓"),
    MetricInfo("part_motion_pri", "Part Motion (prismatic)", "units", "Joints ↓"),
    MetricInfo("type_acc", "Joint type acc.", "%", "Structure ↑", True, True),
    MetricInfo("count_acc", "Part count acc.", "%", "Structure ↑", True, True),
    MetricInfo("psnr", "PSNR", "dB", "Images ↑", False, True),
    MetricInfo("ssim", "SSIM", "", "Images ↑", False, True),
    MetricInfo("mask_iou", "Mask IoU", "%", "Part masks ↑", True, True),
    MetricInfo("mask_acc", "Mask acc.", "%", "Part masks ↑", True, True),
    MetricInfo("mask_f1", "Mask F1", "%", "Part masks ↑", True, True),
]
INFO = {m.key: m for m in METRICS}


# ----------------------------------------------------------------------------- penalties
#: Metrics whose object value is a mean over the object's movable parts: object metric -> (part metric, joint
#: type the part must have or None). Their penalised object value is recomputed from the parts.
_PART_SOURCES = {"cd_m_start": ("cd_m_start", None), "cd_m_end": ("cd_m_end", None), "cd_m": ("cd_m", None),
                 "axis_ang": ("axis_ang", None), "axis_pos": ("axis_pos", "revolute"),
                 "type_acc": ("type_acc", None), "part_motion_rev": ("part_motion", "revolute"),
                 "part_motion_pri": ("part_motion", "prismatic")}


def penalty_cap(key: str, bbox_diag: float | None) -> float | None:
    """The worst value of metric ``key`` (in its stored unit, e.g. 0.0–1.0 for accuracies), given the object's
    bounding-box diagonal ``bbox_diag`` (scene units, over its start and end states; docs/evaluation.md §4.1).

    0 for accuracies, PSNR, SSIM and mask scores; 90° for Axis Ang (its maximum); 180° for revolute Part
    Motion (the largest rotation angle); for the unbounded metrics, the value of a prediction that is off by
    the whole object: Axis Pos 10·d (×10 units), prismatic Part Motion d (units), every Chamfer
    2000·d² (×1000 squared units: each sample one diagonal from its nearest neighbour, both directions).
    None when the cap needs ``bbox_diag`` and it is unknown (scores written before it was recorded).
    """
    base = key.split("@")[0]
    if base in ("type_acc", "count_acc", "psnr", "ssim", "mask_iou", "mask_acc", "mask_f1"):
        return 0.0
    if base == "axis_ang":
        return 90.0
    if base == "part_motion_rev":
        return 180.0
    if bbox_diag is None:
        return None
    d = float(bbox_diag)
    if base == "axis_pos":
        return 10.0 * d
    if base == "part_motion_pri":
        return d
    if base.startswith(("cd_s", "cd_m", "cd_w")):
        return 2000.0 * d * d
    raise KeyError(f"no penalty rule for metric {key!r}")


def _penalised(v: float, cap: float, higher_better: bool) -> float:
    """A scored value, clipped so it is never worse than the failure value ``cap``."""
    return max(v, cap) if higher_better else min(v, cap)


def penalised_object_value(res: dict, k: str) -> float | None:
    """The object's value of metric ``k`` in the penalised mean: scored values clipped to the cap, failures
    (of the object, or of single movable parts for per-part metrics) counted as the cap; None where the
    metric does not apply to the object, or its cap is unknown."""
    hb = k in INFO and INFO[k].higher_better
    cap = penalty_cap(k, res.get("bbox_diag"))
    if k in _PART_SOURCES:
        src, want = _PART_SOURCES[k]
        vals = []
        for p in res.get("parts", []):
            if want is not None and p["type"] != want:
                continue
            if src in p["metrics"]:
                vals.append(p["metrics"][src])
            elif src in p["failures"]:
                vals.append(None)
        if not vals:
            return None
        if cap is None:
            return None
        return float(np.mean([cap if v is None else _penalised(v, cap, hb) for v in vals]))
    if k in res["metrics"]:
        return None if cap is None else _penalised(res["metrics"][k], cap, hb)
    if k in res["failures"]:
        return cap
    return None


# ----------------------------------------------------------------------------- aggregation
def _metric_failed(res: dict, k: str) -> bool:
    return k in res["failures"] or res.get("part_failures", {}).get(k, 0) > 0


def _null_counts(r: dict, k: str, images_submitted: set[str]) -> bool:
    """A null object counts in the completion and penalised mean of an image metric that the submission
    scored elsewhere (the scorer marks it not applicable: with no result there are no images)."""
    return k in images_submitted and r["status"] == "failed" and k not in r["metrics"] and not _metric_failed(r, k)


def _agg(results: list[dict], k: str, images_submitted: set[str] = frozenset()) -> dict:
    vals = [r["metrics"][k] for r in results if k in r["metrics"]]
    nfail = sum(1 for r in results if _metric_failed(r, k))
    applies = [r for r in results if k in r["metrics"] or _metric_failed(r, k) or _null_counts(r, k, images_submitted)]
    complete = sum(1 for r in applies if k in r["metrics"] and not _metric_failed(r, k))
    pen = [penalty_cap(k, None) if _null_counts(r, k, images_submitted) else penalised_object_value(r, k)
           for r in applies]
    return {"mean": float(np.mean(vals)) if vals else None, "n": len(vals), "n_failed": nfail,
            "n_applicable": len(applies), "completion": complete / len(applies) if applies else None,
            "penalised_mean": float(np.mean(pen)) if pen and all(v is not None for v in pen) else None}


def aggregate(results: dict[str, dict]) -> dict:
    """Per-category and overall aggregates of object results (see module docstring)."""
    cats: dict[str, list[dict]] = {}
    for r in results.values():
        cats.setdefault(r["category"], []).append(r)
    images = {k for k in IMAGE_METRICS for r in results.values() if k in r["metrics"] or k in r["failures"]}
    out_c = {}
    for c in sorted(cats):
        rs = cats[c]
        out_c[c] = {"objects": [r["object_id"] for r in rs], "n_objects": len(rs),
                    "n_failed_objects": sum(r["status"] == "failed" for r in rs),
                    "metrics": {k: _agg(rs, k, images) for k in OBJECT_METRICS}}
    mean_cat = {}
    for k in OBJECT_METRICS:
        cs = [out_c[c]["metrics"][k] for c in out_c]
        ms = [m["mean"] for m in cs if m["mean"] is not None]
        applies = [m for m in cs if m["n_applicable"]]
        pen = [m["penalised_mean"] for m in applies]
        mean_cat[k] = {"mean": float(np.mean(ms)) if ms else None, "n_categories": len(ms),
                       "n_failed": sum(m["n_failed"] for m in cs),
                       "n_applicable_categories": len(applies),
                       "completion": float(np.mean([m["completion"] for m in applies])) if applies else None,
                       "penalised_mean": float(np.mean(pen)) if pen and all(v is not None for v in pen) else None}
    all_r = list(results.values())
    n_failed = sum(r["status"] == "failed" for r in all_r)
    return {"categories": out_c, "overall": {
        "n_objects": len(all_r), "n_failed_objects": n_failed,
        "completion": (len(all_r) - n_failed) / len(all_r) if all_r else None,
        "mean_of_categories": mean_cat, "objects": {k: _agg(all_r, k, images) for k in OBJECT_METRICS}}}


def failure_list(results: dict[str, dict]) -> list[dict]:
    """Every failure: object, part (name or None), metric, reason."""
    out = []
    for oid, r in results.items():
        for k, why in r["failures"].items():
            out.append({"object": oid, "part": None, "metric": k, "reason": why})
        for p in r["parts"]:
            for k, why in p["failures"].items():
                out.append({"object": oid, "part": p["name"], "metric": k, "reason": why})
    return out


# ----------------------------------------------------------------------------- tables
def part_rows(results: dict[str, dict]) -> list[dict]:
    rows = []
    for oid, r in results.items():
        for p in r["parts"]:
            row = {"object_id": oid, "category": r["category"], "status": r["status"],
                   "movable_index": p["movable_index"], "part": p["part"], "name": p["name"], "joint": p["joint"],
                   "type": p["type"], "pred": p["pred"], "pred_type": p["pred_type"]}
            row.update({k: p["metrics"].get(k) for k in PART_METRICS})
            row["failures"] = "; ".join(f"{k}: {v}" for k, v in p["failures"].items())
            rows.append(row)
    return rows


def object_rows(results: dict[str, dict]) -> list[dict]:
    rows = []
    for oid, r in results.items():
        row = {"object_id": oid, "category": r["category"], "status": r["status"],
               "n_true_movable": r["n_true_movable"], "n_pred_movable": r.get("n_pred_movable")}
        row.update({k: r["metrics"].get(k) for k in OBJECT_METRICS})
        fails = [f"{k}: {v}" for k, v in r["failures"].items()]
        fails += [f"{k}: {n} part(s) failed" for k, n in r.get("part_failures", {}).items()]
        row["failures"] = "; ".join(fails)
        rows.append(row)
    return rows


def _fmt(v: float, info: MetricInfo) -> str:
    fmt = ".1f" if info.percent or info.key == "psnr" else ".3f"
    return f"{v * (100 if info.percent else 1):{fmt}}"


def _cell(m: dict, info: MetricInfo) -> str:
    star = "*" if m["n_failed"] else ""
    if m["mean"] is None:
        return "*" if star else "–"
    return f"{_fmt(m['mean'], info)}{star}"


def _pen_cell(m: dict, info: MetricInfo) -> str:
    """Penalised mean (failures counted as the worst value, so no ``*``); "–" if not applicable."""
    if not m.get("n_applicable_categories", m.get("n_applicable")):
        return "–"
    return "?" if m.get("penalised_mean") is None else _fmt(m["penalised_mean"], info)


def _completion_cell(m: dict) -> str:
    c = m.get("completion")
    return "–" if c is None else f"{100 * c:.0f} %"


def _units(scores: dict) -> str:
    """The scene units of the scored objects: "m" when every object is metric, else "units"."""
    us = {r.get("units") for r in scores["objects"].values()}
    return "m" if us == {"m"} else "units"


def _unit_label(info: MetricInfo, scores: dict) -> str:
    return info.unit.replace("units", _units(scores))


def summary_markdown(scores: dict) -> str:
    """Paper-style table: metrics as row groups, categories as columns, a Mean column, ``*`` for failures."""
    agg = scores["aggregate"]
    cats = list(agg["categories"])
    present = [m for m in METRICS
               if any(agg["categories"][c]["metrics"][m.key]["n"] or agg["categories"][c]["metrics"][m.key]["n_failed"]
                      for c in cats)]
    meth = scores["submission"]["method"]
    lines = [f"# {meth.get('name', '?')} on {scores['dataset'].get('name') or 'objects'}"
             f"{' / ' + scores['dataset']['split'] if scores['dataset'].get('split') else ''}", "",
             f"rsart {scores['toolkit']['version']}, config `{scores['config_hash'][:12]}`, "
             f"Chamfer states: {scores['config']['states']}; "
             f"{agg['overall']['n_objects']} objects, {agg['overall']['n_failed_objects']} failed (null).", "",
             "| Metric | " + " | ".join(cats) + " | Mean | Penalised mean | Completion |",
             "|---|" + "---:|" * (len(cats) + 3)]
    group = None
    for m in present:
        if m.group != group:
            group = m.group
            lines.append(f"| **{group}** |" + " |" * (len(cats) + 3))
        unit = f" ({_unit_label(m, scores)})" if m.unit else ""
        cells = [_cell(agg["categories"][c]["metrics"][m.key], m) for c in cats]
        mc = agg["overall"]["mean_of_categories"][m.key]
        cells.append(_cell({"mean": mc["mean"], "n_failed": mc["n_failed"]}, m))
        cells += [_pen_cell(mc, m), _completion_cell(mc)]
        lines.append(f"| {m.label}{unit} | " + " | ".join(cells) + " |")
    units = " Lengths in metres." if _units(scores) == "m" else ""
    lines += ["", "`*`: the method failed on at least one object (or part) of that category for this metric; "
              "failures are listed in scores.json and left out of these means, as in the papers. `–`: not "
              "applicable (Axis Pos of prismatic joints, image metrics without submitted images).",
              "Penalised mean: mean over categories, with every failure counted as the metric's worst value "
              "(0 % for accuracies, 90° Axis Ang, 180° revolute Part Motion, caps from the object's size for "
              "Chamfer, Axis Pos and prismatic Part Motion; docs/evaluation.md §4.1), so skipping an object never "
              "helps. Completion: share of objects that scored the metric without failure (mean over categories).",
              f"Chamfer: {scores['config']['chamfer']['n_samples']} area samples per mesh, squared L2, both "
              f"directions summed, ×1000, mean over {len(scores['config']['chamfer']['seeds'])} seed(s) and the "
              f"Chamfer states; component filter {'on' if scores['config']['chamfer']['component_filter'] else 'off'}."
              f"{units} Mean = mean over categories. Formulas: docs/evaluation.md.", ""]
    fl = scores["failures"]
    if fl:
        lines += [f"## Failures ({len(fl)})", ""]
        lines += [f"- {f['object']}{'/' + f['part'] if f['part'] else ''} {f['metric']}: {f['reason']}" for f in fl[:200]]
        if len(fl) > 200:
            lines.append(f"- … {len(fl) - 200} more in scores.json")
        lines.append("")
    return "\n".join(lines)


def plot_bars(scores: dict, key: str) -> list[tuple[str, float | None, str]]:
    """The bars of one summary-plot panel: (label, height in display units or None, note) per category, then
    Mean and Penalised. None means no bar is drawn; the note then says "failed" or "n/a"."""
    agg = scores["aggregate"]
    info = INFO[key]
    scale = 100 if info.percent else 1
    mc = agg["overall"]["mean_of_categories"][key]
    cells = [(c, agg["categories"][c]["metrics"][key]) for c in agg["categories"]]
    cells += [("Mean", {"mean": mc["mean"], "n_failed": mc["n_failed"]}),
              ("Penalised", {"mean": mc.get("penalised_mean"), "n_failed": 0})]
    out = []
    for label, x in cells:
        if x["mean"] is None:
            out.append((label, None, "failed" if x["n_failed"] else "n/a"))
        else:
            out.append((label, x["mean"] * scale, "has failures" if x["n_failed"] else ""))
    return out


def summary_plot(scores: dict) -> bytes:
    """PNG bytes: one panel per metric with values, bars per category (+ Mean); hatched = has failures."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agg = scores["aggregate"]
    cats = list(agg["categories"])
    present = [m for m in METRICS
               if any(agg["categories"][c]["metrics"][m.key]["n"] or agg["categories"][c]["metrics"][m.key]["n_failed"]
                      for c in cats)]
    n = max(1, len(present))
    cols = min(3, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False)
    for ax, m in zip(axes.flat, present):
        bars = plot_bars(scores, m.key)
        xs = [i for i, b in enumerate(bars) if b[1] is not None]  # no bar at all where nothing scored
        drawn = ax.bar(xs, [bars[i][1] for i in xs], color=[("C0", "C1", "C2")[max(0, i - len(cats) + 1)] for i in xs])
        for d, i in zip(drawn, xs):
            if bars[i][2] == "has failures":
                d.set_hatch("//")
        for i, (_label, v, note) in enumerate(bars):
            if v is None:  # "failed" (nothing scored) or "n/a" (not applicable), never a 0-height bar
                ax.text(i, 0, note, rotation=90, ha="center", va="bottom", fontsize=7,
                        color="#a00" if note == "failed" else "#777")
        others = [b[1] for b in bars[:-1] if b[1] is not None]
        pen = bars[-1][1]
        if pen is not None and others and 0 < max(others) and pen > 3 * max(others):
            # a penalised mean far above the rest would flatten every other bar: cut its bar, print its value
            top = 1.3 * max(others)
            ax.set_ylim(0, top)
            ax.text(len(bars) - 1, 0.97 * top, f"{pen:.4g} ↑", ha="center", va="top", fontsize=7, color="C2",
                    bbox=dict(boxstyle="square,pad=0.15", fc="white", ec="none"))
        ax.set_xlim(-0.6, len(bars) - 0.4)
        ax.set_xticks(range(len(bars)), [b[0] for b in bars], rotation=45, ha="right", fontsize=8)
        ax.set_title(f"{m.label}{' (' + _unit_label(m, scores) + ')' if m.unit else ''}", fontsize=9)
    for ax in list(axes.flat)[len(present):]:
        ax.axis("off")
    fig.suptitle(f"{scores['submission']['method'].get('name', '?')}: per-category scores (hatched: failures "
                 "left out; Penalised: failures at the worst value)",
                 fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def write_reports(scores: dict, out: str | Path) -> list[Path]:
    """Write scores.json, scores_per_part.csv, scores_per_object.csv, summary.md, summary.png into ``out``."""
    import pandas as pd

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "scores.json", scores)
    res = scores["objects"]
    for name, rows, cols in (("scores_per_part.csv", part_rows(res), None), ("scores_per_object.csv", object_rows(res), None)):
        df = pd.DataFrame(rows, columns=cols)
        atomic_write_text(out / name, df.to_csv(index=False, na_rep="", float_format="%.6g"))
    atomic_write_text(out / "summary.md", summary_markdown(scores))
    atomic_write_bytes(out / "summary.png", summary_plot(scores))
    return [out / n for n in ("scores.json", "scores_per_part.csv", "scores_per_object.csv", "summary.md",
                              "summary.png")]


def build_scores(results: dict[str, dict], *, config: dict, config_hash: str, toolkit_version: str,
                 dataset: dict[str, Any], submission: dict[str, Any]) -> dict:
    """The scores.json document."""
    from .version import SCORER_VERSION

    return {"format": "rsart-scores/1",
            "toolkit": {"name": "rsart", "version": toolkit_version, "scorer_version": SCORER_VERSION},
            "dataset": dataset, "submission": submission, "config": config, "config_hash": config_hash,
            "aggregate": aggregate(results), "failures": failure_list(results), "objects": results}
