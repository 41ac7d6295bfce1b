"""Hostile uploads and crashes (issue 22), built on the fly, against a real server on 127.0.0.1: a split zip
bomb, refused uploads counted by the rate limit, `kill -9` during extraction then a restart (no bytes
left), and a worker orphaned by a server crash (the job is not scored by two workers at once)."""
from __future__ import annotations

import io
import os
import signal
import threading
import time
import zipfile
from pathlib import Path

import httpx
import pytest

from leaderboards.archive import ArchiveError, extract_zip
from leaderboards.jobs import LEASE_S, create_token, get_job
from leaderboards.schema import open_engine
from lb_helpers import Server, make_submission, zip_folder

MiB = 1024 ** 2


def _add_entries(zip_bytes: bytes, entries, method=zipfile.ZIP_DEFLATED) -> bytes:
    """``zip_bytes`` with more (name, bytes) entries appended."""
    buf = io.BytesIO(zip_bytes)
    with zipfile.ZipFile(buf, "a", method) as zf:
        for name, data in entries:
            zf.writestr(name, data)
    return buf.getvalue()


def _split_bomb(valid: bytes) -> bytes:
    """A valid submission plus 1000 entries of 1 MiB of zeros (about 1 MB compressed)."""
    zeros = b"\0" * MiB
    return _add_entries(valid, ((f"pad/{i:04d}.bin", zeros) for i in range(1000)))


def _leftovers(work: Path) -> list[Path]:
    """Files and temporary folders under the server's work folder (empty folders are not leftovers)."""
    return [p for p in work.rglob("*") if p.is_file() or p.name.endswith(".partial")]


def _bytes_under(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def gt_sub(one_object, lb_root):
    return make_submission(one_object, lb_root / "untrusted_sub")


def test_split_zip_bomb_is_stopped_while_inflating(gt_sub, tmp_path):
    data = _split_bomb(zip_folder(gt_sub))
    assert len(data) < 2 * MiB
    (tmp_path / "a.zip").write_bytes(data)
    with pytest.raises(ArchiveError, match="zip bomb") as e:
        extract_zip(tmp_path / "a.zip", tmp_path / "x")
    msg = str(e.value)
    assert "\n" not in msg and "inflates to more than" in msg, msg
    stopped_at = int(msg.split("pad/")[1][:4])
    assert stopped_at < 100, msg  # stopped after tens of MiB, not 1 GB
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.zip"]  # no partial folder left


@pytest.fixture(scope="module")
def bare_server(one_object, tmp_path_factory):
    """A server without workers and with the default (200 MB) upload limit."""
    root = tmp_path_factory.mktemp("untrusted-srv")
    db = root / "lb.db"
    eng = open_engine(str(db))
    srv = Server(db, one_object, root / "work", workers=0).start()
    srv.tokens = {"main": create_token(eng, "team-u", 100), "three": create_token(eng, "team-three", 3)}
    srv.db = db
    yield srv
    srv.kill()


def test_split_zip_bomb_upload_is_refused_and_leaves_nothing(bare_server, gt_sub):
    r = bare_server.upload(bare_server.tokens["main"], _split_bomb(zip_folder(gt_sub, method="bomb")))
    assert r.status_code == 422 and "zip bomb" in r.json()["error"], r.text
    assert _bytes_under(bare_server.work) == 0
    assert not any((bare_server.work / "jobs").iterdir()) and not _leftovers(bare_server.work)


def test_refused_uploads_count_toward_the_rate_limit(bare_server, gt_sub):
    tok = bare_server.tokens["three"]
    codes = [bare_server.upload(tok, b"not a zip").status_code for _ in range(3)]
    assert codes == [422, 422, 422]
    r = bare_server.upload(tok, zip_folder(gt_sub, method="after-refusals"))
    assert r.status_code == 429 and "rate limit" in r.json()["error"], r.text


def test_kill_during_extraction_then_restart_leaves_no_bytes(one_object, gt_sub, tmp_path):
    db, work = tmp_path / "lb.db", tmp_path / "work"
    tok = create_token(open_engine(str(db)), "team-kill", 100)
    # many stored (uncompressed) entries: extraction takes a while, long enough to be caught in the act
    blob = os.urandom(32 * 1024)
    data = _add_entries(zip_folder(gt_sub, method="killed"), ((f"pad/{i:05d}.bin", blob) for i in range(3000)),
                        method=zipfile.ZIP_STORED)
    srv = Server(db, one_object, work, workers=0).start()
    leftovers = 0
    try:
        t = threading.Thread(target=lambda: _quiet_upload(srv, tok, data), daemon=True)
        t.start()
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # kill as soon as an extraction folder holds bytes
            parts = list((work / "incoming").glob("*/*/.*.partial"))
            if parts and _bytes_under(parts[0]) > 10 * 1024 ** 2:
                os.killpg(srv.proc.pid, signal.SIGKILL)
                break
            time.sleep(0.01)
        else:
            pytest.fail("no extraction seen to interrupt")
        srv.kill()
        t.join(timeout=30)
        leftovers = _bytes_under(work)
        assert list((work / "incoming").glob("*/*.zip")) and list((work / "incoming").glob("*/*/.*.partial"))
        assert leftovers > 10 * 1024 ** 2
    finally:
        srv.kill()
    srv2 = Server(db, one_object, work, workers=0).start()
    try:
        assert _bytes_under(work) == 0, [str(p) for p in work.rglob("*") if p.is_file()][:5]
        assert not any((work / "jobs").iterdir()) and not _leftovers(work)
        assert "leftover" in srv2.log.read_text()
    finally:
        srv2.kill()


def _quiet_upload(srv, tok, data):
    try:
        srv.upload(tok, data, timeout=120)
    except httpx.HTTPError:
        pass  # the server was killed under it


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_orphaned_worker_does_not_score_the_job_twice(one_object, gt_sub, tmp_path):
    db, work = tmp_path / "lb.db", tmp_path / "work"
    eng = open_engine(str(db))
    tok = create_token(eng, "team-orphan", 100)
    slow = ["--chamfer-samples", "60000"]  # a job long enough to crash the server in the middle of it
    srv = Server(db, one_object, work, workers=1, extra=slow).start()
    srv2 = None
    try:
        r = srv.upload(tok, zip_folder(gt_sub, method="orphaned"))
        assert r.status_code == 202, r.text
        job = r.json()["job_id"]
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and get_job(eng, job)["status"] != "running":
            time.sleep(0.05)
        assert get_job(eng, job)["status"] == "running"
        workers = _children(srv.proc.pid)
        assert len(workers) == 1
        orphan = workers[0]
        os.kill(srv.proc.pid, signal.SIGKILL)  # the server only: its worker is orphaned mid-job
        srv.proc.wait(timeout=20)
        died: list[float] = []

        def watch():  # when did the orphan exit? (bounded)
            end = time.monotonic() + 60
            while time.monotonic() < end and _alive(orphan):
                time.sleep(0.05)
            if not _alive(orphan):
                died.append(time.time())

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        srv2 = Server(db, one_object, work, workers=1, extra=slow).start()  # restart at once
        watcher.join(timeout=70)
        assert died, "the orphaned worker kept running"
        orphan_gone = died[0]
        done = srv2.wait_jobs([job], timeout=LEASE_S + 240)[job]
        assert done["status"] == "done", done
        j = get_job(eng, job)
        # either the orphan finished before noticing (one attempt), or the job was claimed again only after
        # the orphan had exited (its lease expired): never two workers on it at once
        assert j["attempts"] == 1 or j["started_at"] >= orphan_gone - 0.5, j
        rows = [x for x in httpx.get(srv2.url + "/api/leaderboard").json() if x["method"] == "orphaned"]
        assert len(rows) == 1
    finally:
        srv.kill()
        if srv2 is not None:
            srv2.kill()


def test_concurrent_unpacking_is_capped(one_object, gt_sub, tmp_path, monkeypatch):
    """Six uploads at once, ``max_unpacking=2``: never more than two archives inflate at the same time (the
    real extractor, timed by a wrapper that counts how many run at once), and every upload is still queued."""
    from concurrent.futures import ThreadPoolExecutor

    from fastapi.testclient import TestClient

    import leaderboards.server as S

    active, peak, lock = [0], [0], threading.Lock()
    real = S.extract_zip

    def counted(*a, **k):
        with lock:
            active[0] += 1
            peak[0] = max(peak[0], active[0])
        try:
            time.sleep(0.3)  # hold the slot long enough for the others to pile up
            return real(*a, **k)
        finally:
            with lock:
                active[0] -= 1

    monkeypatch.setattr(S, "extract_zip", counted)
    cfg = S.ServerConfig(db=str(tmp_path / "lb.db"), data=one_object, work=tmp_path / "work", max_unpacking=2)
    tok = create_token(open_engine(cfg.db), "team-cap", 100)
    datas = [zip_folder(gt_sub, method=f"cap-{i}") for i in range(6)]
    with TestClient(S.create_app(cfg), base_url="http://127.0.0.1") as c, ThreadPoolExecutor(6) as ex:
        rs = list(ex.map(lambda d: c.post(S.UPLOAD_PATH, headers={"Authorization": f"Bearer {tok}"},
                                          files={"archive": ("s.zip", d, "application/zip")}), datas))
    assert [r.status_code for r in rs] == [202] * 6, [r.text for r in rs]
    assert peak[0] == 2, peak
