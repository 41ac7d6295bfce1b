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
    # our tiny dataset has other objects than the paper's tables: no computed row beside published rows
    assert not re.search(r"computed \(tiny v1[^)]*\)", html)
    assert "scored on the same objects in the same units" in html
    # computed ranking tables never contain published rows
    first_rank = html.split('<table class="sortable" id="rank-')[1].split("</table>")[0]
    assert "published" not in first_rank and "PARIS" not in first_rank


def _rank_rows(html: str) -> list[str]:
    first = html.split('<table class="sortable" id="rank-')[1].split("</table>")[0]
    return first.split("<tbody>")[1].split("<tr")[1:]


def test_ranked_by_penalised_mean_with_completion_and_best_highlighted(site):
    html = (site / "index.html").read_text()
    rows = _rank_rows(html)
    names = [re.search(r"<td data-v=\"[^\"]*\">([^<]*)</td>", r.split("</td>", 1)[1]).group(1) for r in rows]
    # the ground truth first; the method that nulled the door object last, although its paper-convention
    # means (door left out) equal the ground truth's
    assert names[0].startswith("ground-truth") and names[-1].startswith("half-failed"), names
    fail_row = rows[-1]
    assert ">50 %<" in fail_row                              # completion: 1 of 2 objects
    # Axis Ang: the null door counts 90°, the drawer 0° -> penalised Mean over categories (90 + 0) / 2 = 45
    assert ">45.000<" in fail_row and "paper convention 0.000*" in fail_row
    assert 'class="n best"' in rows[0]                        # the ground truth holds the best values
    head = html.split('<table class="sortable" id="rank-')[1].split("</thead>")[0]
    assert "Axis Pos (×10 m)" in head and "units" not in head  # the tiny dataset is in metres


def test_failure_marks_and_escaping(site):
    html = (site / "index.html").read_text()
    # half-failed: the door object is null -> its CD cells are '*' alone, the mean cell carries '*'
    rank = [t for t in html.split("<table") if "half-failed" in t and "Paper-style" not in t]
    row = [r for r in html.split("Paper-style table")[1].split("<tr") if "half-failed" in r][0]
    assert 'class="n fail"' in row and re.search(r">\d+\.\d+\*<", row)
    assert rank
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


def test_paper_rows_beside_computed_rows_only_for_the_same_objects_and_units(scored, tmp_path):
    from leaderboards.paper import get_table
    from leaderboards.site import PaperEvalSet, comparison_html
    from leaderboards.store import list_submissions

    eng = open_engine(str(tmp_path / "lb.db"))
    add_scores(eng, scored["perturbed"])
    subs = list_submissions(eng)
    assert subs[0].objects == frozenset({"drawer-0000", "door-0001"}) and subs[0].units == "m"
    t = get_table("partnet_main")
    same = comparison_html(t, subs, {}, PaperEvalSet("m", frozenset({"drawer-0000", "door-0001"})))
    assert "computed (tiny v1 · scorer" in same and "PARIS" in same
    assert comparison_html(t, subs, {}, PaperEvalSet("", frozenset({"drawer-0000", "door-0001"}))) == ""  # units
    assert comparison_html(t, subs, {}, PaperEvalSet("m", frozenset({"drawer-0000"}))) == ""  # objects
    assert comparison_html(t, subs, {}) == ""  # the paper's own objects are not listed: never beside


def test_one_row_per_run_best_per_method_unless_all_runs(scored, tmp_path):
    from leaderboards.site import leaderboard_sections
    from leaderboards.store import list_submissions

    eng = open_engine(str(tmp_path / "lb.db"))
    # two runs of one method: the perturbed one, and the ground truth relabelled as the same method
    runs = []
    for key, label in (("perturbed", "tilted"), ("gt", "exact")):
        d = tmp_path / key
        shutil.copytree(scored[key], d)
        doc = json.loads((d / "scores.json").read_text())
        doc["submission"]["method"]["name"] = "mymethod"
        if key == "gt":
            doc["submission"]["method"]["lr"] = 0.01  # another setting -> another config hash
        (d / "scores.json").write_text(json.dumps(doc))
        runs.append(add_scores(eng, d, label=label)[0])
    subs = list_submissions(eng)
    assert [s.run for s in subs] == ["tilted", "exact"]
    assert subs[0].run_config_hash != subs[1].run_config_hash
    best = _rank_rows(leaderboard_sections(subs))
    assert len(best) == 1 and ">exact<" in best[0]          # the better-ranked run stands for the method
    every = _rank_rows(leaderboard_sections(subs, all_runs=True))
    assert len(every) == 2 and ">exact<" in every[0] and ">tilted<" in every[1]
    assert f">{subs[0].run_config_hash[:8]}<" in every[1]
