"""Shared helpers for the leaderboards tests: a tiny generated dataset, reference submissions, zips, a real
server in a subprocess on 127.0.0.1."""
from __future__ import annotations

import io
import json
import os
import signal
import socket
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[2]
PY = sys.executable
FAST_EVAL = ["--chamfer-samples", "300", "--chamfer-seeds", "0", "--workers", "1"]


def build_dataset(root: Path, objects=(("drawer", 0), ("door", 1))) -> Path:
    """Procedural objects written with rsart's writer + index.json (name "tiny", version "1")."""
    from rsart.format import DatasetIndex, write_index
    from rsart.sources.procedural.registry import generate
    from rsart.twin_io import write_object

    ids = []
    for cat, seed in objects:
        g = generate(cat, seed)
        write_object(g.twin, root / g.object_id, object_id=g.object_id, category=g.category, source=g.source,
                     write_usd=False)
        ids.append(g.object_id)
    write_index(DatasetIndex("tiny", "1", ids, {"test": ids}), root)
    return root


def make_submission(data: Path, out: Path, perturb: str | None = None, method: str | None = None,
                    null: tuple[str, ...] = ()) -> Path:
    """A GT (or perturbed) submission folder; optionally renamed method and null (failed) objects."""
    from rsart.evaluation import load_ground_truth, make_gt_submission
    from rsart.evaluation.gt_submission import parse_perturbation

    make_gt_submission(load_ground_truth(data), out, "start,end", parse_perturbation(perturb) if perturb else None)
    f = out / "submission.json"
    d = json.loads(f.read_text())
    if method:
        d["method"]["name"] = method
    for oid in null:
        d["results"][oid] = None
    f.write_text(json.dumps(d))
    return out


def score(sub_dir: Path, data: Path, out: Path) -> Path:
    """Run the real rsart-eval CLI (small Chamfer settings) → its output folder."""
    return score_many([(sub_dir, data, out)])[0]


def score_many(jobs: list[tuple[Path, Path, Path]]) -> list[Path]:
    """Several rsart-eval runs at once (sub_dir, data, out) → output folders."""
    procs = [subprocess.Popen([PY, "-m", "rsart.evaluation.cli", str(s / "submission.json"), "--data", str(d),
                               "--out", str(o), *FAST_EVAL], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, cwd=REPO, env=env()) for s, d, o in jobs]
    for p in procs:
        _out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    return [o for _s, _d, o in jobs]


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(REPO) + (os.pathsep + e["PYTHONPATH"] if e.get("PYTHONPATH") else "")
    return e


def zip_folder(folder: Path, method: str | None = None) -> bytes:
    """Zip a submission folder in memory (optionally renaming the method, which changes its identity)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                data = p.read_bytes()
                if p.name == "submission.json" and method:
                    d = json.loads(data)
                    d["method"]["name"] = method
                    data = json.dumps(d).encode()
                zf.writestr(str(p.relative_to(folder)), data)
    return buf.getvalue()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``rsart leaderboard serve`` in its own process group on 127.0.0.1 (stopped by its pid only)."""

    def __init__(self, db: Path, data: Path, work: Path, workers: int = 2, extra: list[str] | None = None,
                 log: Path | None = None):
        self.db, self.data, self.work, self.workers = db, data, work, workers
        self.extra = extra or []
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = log or work.parent / f"server-{self.port}.log"
        self.proc: subprocess.Popen | None = None

    def start(self, timeout: float = 60.0) -> "Server":
        argv = [PY, "-m", "leaderboards.cli", "serve", "--db", str(self.db), "--data", str(self.data), "--work",
                str(self.work), "--port", str(self.port), "--workers", str(self.workers),
                "--chamfer-samples", "300", "--chamfer-seeds", "0", *self.extra]
        self._logf = open(self.log, "ab")
        self.proc = subprocess.Popen(argv, cwd=REPO, env=env(), stdout=self._logf, stderr=subprocess.STDOUT,
                                     start_new_session=True)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited: {self.log.read_text()[-2000:]}")
            try:
                if httpx.get(self.url + "/healthz", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise RuntimeError(f"server did not start in {timeout}s: {self.log.read_text()[-2000:]}")

    def kill(self, sig: int = signal.SIGKILL) -> None:
        """Signal the server's process group (the server and its workers), then reap it."""
        if self.proc is None:
            return
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(timeout=10)
        self._logf.close()
        self.proc = None

    def upload(self, token: str | None, data: bytes, timeout: float = 60.0) -> httpx.Response:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.post(self.url + "/api/submissions", headers=headers,
                          files={"archive": ("sub.zip", data, "application/zip")}, timeout=timeout)

    def wait_jobs(self, ids: list[str], timeout: float = 120.0) -> dict[str, dict]:
        """Poll until every job is done or failed (bounded) → id → status record."""
        deadline = time.monotonic() + timeout
        out: dict[str, dict] = {}
        while time.monotonic() < deadline:
            for j in ids:
                if j in out:
                    continue
                try:
                    r = httpx.get(f"{self.url}/api/jobs/{j}", timeout=30.0).json()
                except httpx.TimeoutException:  # a starved machine (CI beside a benchmark): ask again until
                    continue                    # the deadline instead of failing on one slow answer
                if r["status"] in ("done", "failed"):
                    out[j] = r
            if len(out) == len(ids):
                return out
            time.sleep(0.3)
        raise AssertionError(f"jobs not finished in {timeout}s: {sorted(set(ids) - set(out))[:5]}")
