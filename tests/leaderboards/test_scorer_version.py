"""Rows scored by different scorer versions are shown with their version and never ranked together."""
from __future__ import annotations

import json
import sqlite3

from leaderboards.schema import open_engine
from leaderboards.site import group_subs
from leaderboards.store import add_scores, list_submissions
from rsart.evaluation.version import SCORER_VERSION


def test_scorer_versions_are_never_ranked_together(scored, tmp_path):
    doc = json.loads((scored["gt"] / "scores.json").read_text())
    assert doc["toolkit"]["scorer_version"] == SCORER_VERSION
    older = json.loads(json.dumps(doc))
    older["toolkit"]["scorer_version"] = "0-test"
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "scores.json").write_text(json.dumps(older))
    eng = open_engine(str(tmp_path / "lb.db"))
    a, created_a = add_scores(eng, scored["gt"])
    b, created_b = add_scores(eng, tmp_path / "old")
    assert created_a and created_b and a != b  # same scores, other scorer version: another row
    subs = {s.id: s for s in list_submissions(eng)}
    assert subs[a].scorer_version == SCORER_VERSION and subs[b].scorer_version == "0-test"
    groups = group_subs(list(subs.values()))
    assert len(groups) == 2, list(groups)  # one ranking per scorer version
    assert any(f"scorer {SCORER_VERSION}" in label for label in groups)


def test_store_made_before_scorer_versions_gets_the_column(scored, tmp_path):
    db = tmp_path / "old.db"
    eng = open_engine(str(db))
    add_scores(eng, scored["gt"])
    eng.dispose()
    con = sqlite3.connect(db)  # make it look like a store from before the column existed
    con.execute("ALTER TABLE submissions DROP COLUMN scorer_version")
    con.commit()
    con.close()
    subs = list_submissions(open_engine(str(db)))
    assert [s.scorer_version for s in subs] == ["0"]
