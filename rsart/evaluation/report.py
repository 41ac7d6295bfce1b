"""Aggregation and reports: scores.json, per-part/per-object CSVs, summary.md, summary.png.

Aggregation rules (docs/evaluation.md):

* object value of a per-part metric = mean over the object's movable parts that scored it;
* category value = mean over its objects that scored the metric; ``n_failed`` counts objects where the
  metric failed for the object or for any of its parts (then the table cell carries ``*``);
* Mean column = mean of the category values (every category weighs the same, as in the papers' tables);
  ``overall.objects`` also gives the plain mean over objects;
* failures never enter a mean as numbers; not-applicable metrics (Axis Pos of prismatic joints, image
  metrics without submitted images) are neither values nor failures and show as "–".
"""
from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..io import atomic_write_bytes, atomic_write_text, write_json
from .score import OBJECT_METRICS, PART_METRICS


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


# ----------------------------------------------------------------------------- aggregation
def _metric_failed(res: dict, k: str) -> bool:
    return k in res["failures"] or res.get("part_failures", {}).get(k, 0) > 0


def _agg(results: list[dict], k: str) -> dict:
    vals = [r["metrics"][k] for r in results if k in r["metrics"]]
    nfail = sum(1 for r in results if _metric_failed(r, k))
    return {"mean": float(np.mean(vals)) if vals else None, "n": len(vals), "n_failed": nfail}


def aggregate(results: dict[str, dict]) -> dict:
    """Per-category and overall aggregates of object results (see module docstring)."""
    cats: dict[str, list[dict]] = {}
    for r in results.values():
        cats.setdefault(r["category"], []).append(r)
    out_c = {}
    for c in sorted(cats):
        rs = cats[c]
        out_c[c] = {"objects": [r["object_id"] for r in rs], "n_objects": len(rs),
                    "n_failed_objects": sum(r["status"] == "failed" for r in rs),
                    "metrics": {k: _agg(rs, k) for k in OBJECT_METRICS}}
    mean_cat = {}
    for k in OBJECT_METRICS:
        ms = [out_c[c]["metrics"][k]["mean"] for c in out_c if out_c[c]["metrics"][k]["mean"] is not None]
        mean_cat[k] = {"mean": float(np.mean(ms)) if ms else None, "n_categories": len(ms),
                       "n_failed": sum(out_c[c]["metrics"][k]["n_failed"] for c in out_c)}
    all_r = list(results.values())
    return {"categories": out_c, "overall": {
        "n_objects": len(all_r), "n_failed_objects": sum(r["status"] == "failed" for r in all_r),
        "mean_of_categories": mean_cat, "objects": {k: _agg(all_r, k) for k in OBJECT_METRICS}}}


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


def _cell(m: dict, info: MetricInfo) -> str:
    star = "*" if m["n_failed"] else ""
    if m["mean"] is None:
        return "*" if star else "–"
    v = m["mean"] * (100 if info.percent else 1)
    fmt = ".1f" if info.percent or info.key == "psnr" else ".3f"
    return f"{v:{fmt}}{star}"


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
             "| Metric | " + " | ".join(cats) + " | Mean |",
             "|---|" + "---:|" * (len(cats) + 1)]
    group = None
    for m in present:
        if m.group != group:
            group = m.group
            lines.append(f"| **{group}** |" + " |" * (len(cats) + 1))
        unit = f" ({_unit_label(m, scores)})" if m.unit else ""
        cells = [_cell(agg["categories"][c]["metrics"][m.key], m) for c in cats]
        mc = agg["overall"]["mean_of_categories"][m.key]
        cells.append(_cell({"mean": mc["mean"], "n_failed": mc["n_failed"]}, m))
        lines.append(f"| {m.label}{unit} | " + " | ".join(cells) + " |")
    lines += ["", "`*`: the method failed on at least one object (or part) of that category for this metric; "
              "failures are listed in scores.json and never averaged. `–`: not applicable (Axis Pos of "
              "prismatic joints, image metrics without submitted images).",
              f"Chamfer: {scores['config']['chamfer']['n_samples']} area samples per mesh, squared L2, both "
              f"directions summed, ×1000, mean over {len(scores['config']['chamfer']['seeds'])} seed(s) and the "
              f"Chamfer states; component filter {'on' if scores['config']['chamfer']['component_filter'] else 'off'}. "
              f"Units: {_units(scores)}. Mean = mean over categories. Formulas: docs/evaluation.md.", ""]
    fl = scores["failures"]
    if fl:
        lines += [f"## Failures ({len(fl)})", ""]
        lines += [f"- {f['object']}{'/' + f['part'] if f['part'] else ''} {f['metric']}: {f['reason']}" for f in fl[:200]]
        if len(fl) > 200:
            lines.append(f"- … {len(fl) - 200} more in scores.json")
        lines.append("")
    return "\n".join(lines)


def summary_plot(scores: dict) -> bytes:
    """PNG bytes: one panel per metric with values, bars per category (+ Mean); hatched = has failures."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agg = scores["aggregate"]
    cats = list(agg["categories"])
    present = [m for m in METRICS if any(agg["categories"][c]["metrics"][m.key]["n"] for c in cats)]
    n = max(1, len(present))
    cols = min(3, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False)
    labels = cats + ["Mean"]
    for ax, m in zip(axes.flat, present):
        ms = [agg["categories"][c]["metrics"][m.key] for c in cats]
        mc = agg["overall"]["mean_of_categories"][m.key]
        ms.append({"mean": mc["mean"], "n_failed": mc["n_failed"]})
        vals = [(x["mean"] or 0.0) * (100 if m.percent else 1) for x in ms]
        bars = ax.bar(range(len(labels)), vals, color=["C0"] * len(cats) + ["C1"])
        for b, x in zip(bars, ms):
            if x["n_failed"]:
                b.set_hatch("//")
        ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right", fontsize=8)
        ax.set_title(f"{m.label}{' (' + _unit_label(m, scores) + ')' if m.unit else ''}", fontsize=9)
    for ax in list(axes.flat)[len(present):]:
        ax.axis("off")
    fig.suptitle(f"{scores['submission']['method'].get('name', '?')}: per-category scores (hatched: failures)",
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
