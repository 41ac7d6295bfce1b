"""The PD²GS paper's published tables, transcribed from pd2gs.tex into ``leaderboards/data/paper/*.json``.

Each file holds one LaTeX table: its label, the line numbers of its caption and label in pd2gs.tex, the
column names and one row per (group, method[, variant]) with the cells exactly as printed, the LaTeX
formatting (bold, colours) removed. Cell text:

* ``"12.34"`` — a value; ``"12.34*"`` — a value, and the method failed on at least one object of that
  column (the paper's superscript ``*``); ``"F"`` — the method failed (no value);
* ``"--"`` or ``"-"`` — not applicable (prismatic joints have no Axis Pos).

These rows are *published* numbers, not re-run here; the site shows them apart from computed rankings.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

DATA_DIR = Path(__file__).parent / "data" / "paper"
FORMAT = "rsart-paper-table/1"

#: Inputs each published method uses (the main table's caption: DTArt needs depth, the others RGB).
PAPER_METHOD_INPUTS = {"DTArt": "rgbd"}
DISPLAY = {"PD2GS": "PD²GS", "D2NeRF": "D²NeRF"}
_NUM = re.compile(r"^-?\d+(\.\d+)?$")


@dataclass(frozen=True)
class PaperCell:
    """One published cell: ``text`` as printed; ``value`` (None if failed or n/a); ``failed`` (the
    method failed on ≥1 object of the column: ``*`` or ``F``); ``applicable`` (False for "--")."""

    text: str
    value: float | None
    failed: bool
    applicable: bool


def parse_cell(text: str) -> PaperCell:
    """Parse a transcribed cell (see module docstring); raises ValueError on anything else."""
    t = text.strip()
    if t in ("--", "-", "–"):
        return PaperCell(t, None, False, False)
    if t == "F":
        return PaperCell(t, None, True, True)
    star = t.endswith("*")
    num = t[:-1] if star else t
    if not _NUM.match(num):
        raise ValueError(f"not a paper cell: {text!r}")
    return PaperCell(t, float(num), star, True)


@dataclass(frozen=True)
class PaperRow:
    method: str
    variant: str
    group: str | None
    lines: tuple[int, int]
    cells: tuple[PaperCell, ...]

    @property
    def display(self) -> str:
        name = DISPLAY.get(self.method, self.method)
        return f"{name} {self.variant}".strip()


@dataclass(frozen=True)
class PaperTable:
    """A published table (``source``: file, label, label_line, caption_line, table_lines)."""

    key: str
    title: str
    dataset: str
    source: dict
    group_kind: str
    columns: tuple[str, ...]
    rows: tuple[PaperRow, ...]

    def cite(self) -> str:
        s = self.source
        return (f"{s['file']} \\label{{{s['label']}}} (line {s['label_line']}, caption line {s['caption_line']}, "
                f"table lines {s['table_lines'][0]}–{s['table_lines'][1]})")

    def groups(self) -> list[str | None]:
        out: list[str | None] = []
        for r in self.rows:
            if r.group not in out:
                out.append(r.group)
        return out


def _table(doc: dict, path: Path) -> PaperTable:
    if doc.get("format") != FORMAT:
        raise ValueError(f"{path}: format is not {FORMAT}")
    cols = tuple(doc["columns"])
    rows = []
    for i, r in enumerate(doc["rows"]):
        if len(r["cells"]) != len(cols):
            raise ValueError(f"{path}: rows[{i}] has {len(r['cells'])} cells for {len(cols)} columns")
        rows.append(PaperRow(r["method"], r.get("variant", ""), r.get("group"), tuple(r["lines"]),
                             tuple(parse_cell(c) for c in r["cells"])))
    return PaperTable(doc["key"], doc["title"], doc["dataset"], doc["source"], doc.get("group_kind", "metric"),
                      cols, tuple(rows))


@lru_cache(maxsize=4)
def load_tables(data_dir: str | None = None) -> tuple[PaperTable, ...]:
    """All published tables, in a fixed order (main table first)."""
    d = Path(data_dir) if data_dir else DATA_DIR
    order = ["partnet_main", "partnet_three_part_joints", "partnet_three_part_geometry", "partnet_five_part",
             "rsart_main", "partnet_two_states", "pose_perturbation", "unseen_state_rendering", "timing"]
    files = sorted(d.glob("*.json"), key=lambda p: (order.index(p.stem) if p.stem in order else 99, p.stem))
    return tuple(_table(json.loads(p.read_text(encoding="utf-8")), p) for p in files)


def get_table(key: str) -> PaperTable:
    for t in load_tables():
        if t.key == key:
            return t
    raise KeyError(key)
