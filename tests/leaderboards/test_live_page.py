"""The live page's reload contract over plain HTTP (no browser), with the browser test's process layout:
``rsart leaderboard serve`` in a subprocess with one worker process writing to the same SQLite file.

The page stamps the version it was rendered from into ``<meta name="rsart-live-version">``; its script
reloads when ``/api/version``'s ``key`` differs. Issue 11: the script used to take its baseline from its
first poll (1.5 s after load), so a submission scored within that window never appeared.
"""
from __future__ import annotations

import re

import httpx

from leaderboards.jobs import create_token
from leaderboards.schema import open_engine
from leaderboards.server import VERSION_META
from lb_helpers import Server, make_submission, zip_folder

STAMP = re.compile(r'<meta name="%s" content="([^"]*)">' % re.escape(VERSION_META))


def _stamp(html: str) -> str:
    m = STAMP.search(html)
    assert m, f"live page has no {VERSION_META} stamp"
    return m.group(1)


def _key(srv: Server) -> str:
    return httpx.get(srv.url + "/api/version", timeout=5.0).json()["key"]


def test_page_loaded_before_a_score_sees_a_new_version(one_object, tmp_path):
    sub = make_submission(one_object, tmp_path / "sub")
    db = tmp_path / "lb.db"
    tok = create_token(open_engine(str(db)), "team-live", 10)
    srv = Server(db, one_object, tmp_path / "work", workers=1).start()
    try:
        before = httpx.get(srv.url + "/", timeout=30.0).text
        assert "No scored submissions yet" in before
        stamp0 = _stamp(before)
        assert stamp0 == _key(srv)  # idle: the page is current, so it must not reload
        assert f"meta[name={VERSION_META}]" in before  # the script compares against the stamp

        r = srv.upload(tok, zip_folder(sub, method="live-new-method"))
        assert r.status_code == 202, r.text
        job = r.json()["job_id"]
        assert srv.wait_jobs([job])[job]["status"] == "done"

        # the page rendered before the score landed must see a different key, however late it first polls
        key1 = _key(srv)
        assert key1 != stamp0
        after = httpx.get(srv.url + "/", timeout=30.0).text  # what the reload shows
        assert "live-new-method" in after and "No scored submissions yet" not in after
        assert _stamp(after) == key1  # the reloaded page is current: no reload loop
    finally:
        srv.kill()
