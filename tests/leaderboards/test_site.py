"""Static site: computed rows beside published rows, failure marks, escaping, offline pages, exports."""
from __future__ import annotations

import csv
import io
import json
import re
import shutil

import pytest

from leaderboards.exports import build_site
from leaderboards.schema import open_engine
from leaderboards.store import add_scores


@pytest.fixture(scope="module")
def site(scored, tmp_path_factory):
    root = tmp_path_factory.mktemp("site")
    # a hostile method name must come out escaped
    hostile = root / "eval_hostile"
    shutil.copytree(scored["perturbed"], hostile)
    doc = json.loads((hostile / "scores.json").read_text())
    doc["submission"]["method"]["name"] = "<script>alert(1)</script>"
    doc["submission"]["sha256"] = "0" * 64
    (hostile / "scores.json").write_text(json.dumps(doc))
    eng = open_engine(str(root / "lb.db"))
    for d in (scored["gt"], scored["perturbed"], scored["failed"], hostile):
        add_scores(eng, d)
    out = build_site(eng, root / "site")
    return out


def test_pages_and_exports_exist(site):
    for f in ("index.html", "published.html", "metrics.html", "methods.html", "downloads.html", "leaderboard.md",
              "leaderboard.csv", "leaderboard_by_category.csv", "published.csv"):
        assert (site / f).is_file(), f
    pngs = list((site / "methods").glob("*.png"))
    assert len(pngs) == 4 and all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    assert len(list((site / "methods").glob("*.html"))) == 4


def test_index_shows_computed_beside_published(site):
    html = (site / "index.html").read_text()
    assert "computed here" in html and "published rows, not re-run here" in html
    assert "ground-truth 0.1.0" in html and "perturbed" in html and "half-failed" in html
    # the paper's main-table rows with its failure marks, and the source citation
    assert "64.35*" in html and "table:sota" in html and "line 561" in html
    # our drawer/door categories land in the paper layout's Door column; drawer is an RS-Art column
    assert re.search(r"computed \(tiny v1[^)]*\)", html)
    # computed ranking tables never contain published rows
    first_rank = html.split('<table class="sortable" id="rank-')[1].split("</table>")[0]
    assert "published" not in first_rank and "PARIS" not in first_rank


def test_failure_marks_and_escaping(site):
    html = (site / "index.html").read_text()
    # half-failed: the door object is null -> its CD cells are '*' alone, the mean cell carries '*'
    rank = [t for t in html.split("<table") if "half-failed" in t][0]
    row = [r for r in rank.split("<tr") if "half-failed" in r][0]
    assert 'class="n fail"' in row and re.search(r">\d+\.\d+\*<", row)
    assert "<script>alert(1)</script>" not in html
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_pages_are_offline(site):
    for p in list(site.glob("*.html")) + list((site / "methods").glob("*.html")):
        text = p.read_text()
        assert not re.search(r"""(src|href)=["']?(https?:)?//""", text), p
        assert "<script>" in text and "sortable" in (text if p.name == "index.html" else "sortable")


def test_exports_parse(site):
    rows = list(csv.DictReader(io.StringIO((site / "leaderboard.csv").read_text())))
    assert {r["method"] for r in rows} >= {"ground-truth", "perturbed", "half-failed"}
    pert = [r for r in rows if r["method"] == "perturbed" and r["metric"] == "axis_ang"]
    assert float(pert[0]["value"]) == pytest.approx(5.0, abs=1e-6)
    pub = list(csv.DictReader(io.StringIO((site / "published.csv").read_text())))
    assert all(r["status"] == "published, not re-run here" for r in pub)
    cell = [r for r in pub if r["table"] == "partnet_main" and r["method"] == "PARIS" and r["group"] == "Axis Ang 0"
            and r["column"] == "Eyeglasses"][0]
    assert cell["text"] == "64.35*" and cell["failed"] == "1"
    md = (site / "leaderboard.md").read_text()
    assert "| perturbed" in md and "5.000" in md


def test_build_replaces_atomically(site, scored, tmp_path):
    eng = open_engine(str(tmp_path / "empty.db"))
    out = build_site(eng, tmp_path / "s")
    assert "No scored submissions yet" in (out / "index.html").read_text()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".s.")]
