"""The submission server, for real: uvicorn in a subprocess on 127.0.0.1, uploads over HTTP, worker processes."""
from __future__ import annotations

import io
import json
import os
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest

from leaderboards.jobs import create_token, revoke_team
from leaderboards.schema import open_engine
from lb_helpers import Server, make_submission, zip_folder


@pytest.fixture(scope="module")
def gt_sub(one_object, lb_root):
    return make_submission(one_object, lb_root / "srv_sub")


@pytest.fixture(scope="module")
def server(one_object, tmp_path_factory):
    root = tmp_path_factory.mktemp("srv")
    db = root / "lb.db"
    eng = open_engine(str(db))
    tokens = {"main": create_token(eng, "team-main", 100), "slow": create_token(eng, "team-slow", 2),
              "revoked": create_token(eng, "team-gone", 100)}
    revoke_team(eng, "team-gone")
    srv = Server(db, one_object, root / "work", workers=2, extra=["--max-upload-mb", "1"]).start()
    srv.tokens = tokens
    yield srv
    srv.kill()


def _zip_entries(entries: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in entries.items():
            zf.writestr(k, v)
    return buf.getvalue()


def test_upload_is_scored_and_appears(server, gt_sub):
    r = server.upload(server.tokens["main"], zip_folder(gt_sub, method="uploaded-gt"))
    assert r.status_code == 202, r.text
    job = r.json()["job_id"]
    done = server.wait_jobs([job])[job]
    assert done["status"] == "done" and done["submission_id"], done
    rows = httpx.get(server.url + "/api/leaderboard").json()
    me = [x for x in rows if x["method"] == "uploaded-gt"]
    assert len(me) == 1 and me[0]["team"] == "team-main"
    assert me[0]["mean"]["axis_ang"]["value"] == pytest.approx(0.0, abs=1e-9)
    # the ground truth completes every object, so its penalised mean is its plain mean
    assert me[0]["completion"] == 1.0 and me[0]["mean"]["axis_ang"]["penalised"] == pytest.approx(0.0, abs=1e-9)
    assert me[0]["scorer_version"] not in (None, "0") and me[0]["run"]
    page = httpx.get(server.url + "/").text
    assert "uploaded-gt" in page and "published rows, not re-run here" in page


def test_auth_failures(server, gt_sub):
    data = zip_folder(gt_sub)
    for tok in (None, "not-a-token", server.tokens["revoked"]):
        r = server.upload(tok, data)
        assert r.status_code == 401, (tok, r.text)
        assert "token" in r.json()["error"]


def test_oversize_upload_refused_before_reading(server):
    r = server.upload(server.tokens["main"], os.urandom(2 * 1024 * 1024))
    assert r.status_code == 413 and "too large" in r.json()["error"]


@pytest.mark.parametrize("entries,needle", [
    ({"submission.json": b"{}", "../../escape.txt": b"x"}, "zip-slip"),
    ({"submission.json": b"{}", "bomb.ply": b"\0" * (40 * 1024 ** 2)}, "zip bomb"),
])
def test_unsafe_archives(server, entries, needle):
    r = server.upload(server.tokens["main"], _zip_entries(entries))
    assert r.status_code == 422, r.text
    assert needle in r.json()["error"]
    assert not (server.work.parent / "escape.txt").exists() and not (server.work / "escape.txt").exists()


def test_not_a_zip(server):
    r = server.upload(server.tokens["main"], b"hello, not a zip")
    assert r.status_code == 422 and "not a zip" in r.json()["error"]


def test_malformed_submission_lists_problems(server, gt_sub):
    d = json.loads((gt_sub / "submission.json").read_text())
    oid = next(iter(d["results"]))
    mov = [k for k in d["results"][oid]["parts"] if k != "static"][0]
    d["results"][oid]["parts"][mov]["joint"]["axis"] = [0, 0, 0]
    files = {str(p.relative_to(gt_sub)): p.read_bytes() for p in gt_sub.rglob("*") if p.is_file()}
    files["submission.json"] = json.dumps(d).encode()
    r = server.upload(server.tokens["main"], _zip_entries(files))
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["error"].startswith("invalid submission")
    assert any("axis" in p["path"] and "zero" in p["message"] for p in body["problems"]), body
    assert all(str(server.work) not in p["message"] for p in body["problems"]), "server paths leaked"
    bad_json = server.upload(server.tokens["main"], _zip_entries({"submission.json": b"{oops"}))
    assert bad_json.status_code == 422 and "invalid JSON" in bad_json.json()["problems"][0]["message"]
    assert str(server.work) not in bad_json.text
    r2 = server.upload(server.tokens["main"], _zip_entries({"x/readme.txt": b"hi"}))
    assert r2.status_code == 422 and "no submission.json" in r2.json()["error"]


def test_bad_mesh_content_fails_the_job_with_a_reason(server, gt_sub):
    files = {str(p.relative_to(gt_sub)): p.read_bytes() for p in gt_sub.rglob("*") if p.is_file()}
    ply = next(k for k in files if k.endswith("static.ply"))
    files[ply] = b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n"  # truncated
    d = json.loads(files["submission.json"])
    d["method"]["name"] = "broken-mesh"
    files["submission.json"] = json.dumps(d).encode()
    r = server.upload(server.tokens["main"], _zip_entries(files))
    assert r.status_code == 202, r.text
    job = server.wait_jobs([r.json()["job_id"]])[r.json()["job_id"]]
    assert job["status"] == "failed" and "static.ply" in job["error"], job


def test_rate_limit(server, gt_sub):
    codes = [server.upload(server.tokens["slow"], zip_folder(gt_sub, method=f"slow-{i}")).status_code
             for i in range(3)]
    assert codes == [202, 202, 429]


def test_twenty_concurrent_uploads_all_scored(server, gt_sub):
    datas = [zip_folder(gt_sub, method=f"concurrent-{i:02d}") for i in range(20)]
    with ThreadPoolExecutor(max_workers=20) as ex:
        resps = list(ex.map(lambda d: server.upload(server.tokens["main"], d, timeout=120), datas))
    assert [r.status_code for r in resps] == [202] * 20, [r.text for r in resps if r.status_code != 202]
    ids = [r.json()["job_id"] for r in resps]
    res = server.wait_jobs(ids, timeout=240)
    assert all(v["status"] == "done" for v in res.values()), [v for v in res.values() if v["status"] != "done"]
    assert len({v["submission_id"] for v in res.values()}) == 20
    names = {x["method"] for x in httpx.get(server.url + "/api/leaderboard").json()}
    assert {f"concurrent-{i:02d}" for i in range(20)} <= names


N_CRASH = 8


def test_kill_mid_queue_and_restart_finishes_every_job(one_object, gt_sub, tmp_path):
    db = tmp_path / "lb.db"
    tok = create_token(open_engine(str(db)), "team-crash", 100)
    # the queue is filled by a server without workers, so no job can finish before the kill (with a worker
    # running during the uploads, a loaded machine let it keep pace and finish all of them: flaky)
    queue = Server(db, one_object, tmp_path / "work", workers=0).start()
    try:
        datas = [zip_folder(gt_sub, method=f"crash-{i}") for i in range(N_CRASH)]
        with ThreadPoolExecutor(max_workers=4) as ex:
            ids = [r.json()["job_id"] for r in ex.map(lambda d: queue.upload(tok, d, timeout=120), datas)]
        assert all(httpx.get(f"{queue.url}/api/jobs/{j}").json()["status"] == "queued" for j in ids)
    finally:
        queue.kill()
    srv = Server(db, one_object, tmp_path / "work", workers=1).start()
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # kill while a job is being scored
            if httpx.get(f"{srv.url}/api/jobs/{ids[0]}").json()["status"] in ("running", "done"):
                break
            time.sleep(0.05)
        srv.kill()
    finally:
        srv.kill()
    from leaderboards.jobs import queue_counts

    before = queue_counts(open_engine(str(db)))
    assert before.get("done", 0) < N_CRASH, before  # the kill really interrupted the queue
    srv2 = Server(db, one_object, tmp_path / "work", workers=2).start()
    try:
        res = srv2.wait_jobs(ids, timeout=180)
        assert all(v["status"] == "done" for v in res.values()), res
        names = {x["method"] for x in httpx.get(srv2.url + "/api/leaderboard").json()}
        assert names == {f"crash-{i}" for i in range(N_CRASH)}
    finally:
        srv2.kill()
