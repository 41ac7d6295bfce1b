"""`pd2gs run --backend process|ray`: same submission on both backends, after a killed worker, after Ctrl-C.

Two tiny rendered objects, 40 training iterations, discovery without refinement/articulation (the stages
the runner schedules are all there; only their cost is cut). Submissions are compared byte for byte.
"""
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

REPO = Path(__file__).resolve().parents[2]
# --threads 1 everywhere: bitwise equality needs one thread count (the default, cores / workers, would
# differ between the 1- and 2-worker runs)
FAST = ["--iters", "40", "--size", "64x48", "--mode", "paper", "--no-refine", "--quiet", "--threads", "1"]


def _variant(**settings) -> str:
    from pd2gs.discovery.config import DiscoveryConfig
    from pd2gs.runner import variant_name

    return variant_name(DiscoveryConfig(**settings))


VARIANT = _variant(mode="paper", refine=False)  # FAST's discovery settings


def _has_ray() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        if os.environ.get("RSART_REQUIRE_RAY"):  # `make test`: CI installs ray; a skip would hide the tests
            raise RuntimeError("RSART_REQUIRE_RAY is set but ray is not installed (pip install 'rsart[ray]')")
        return False
    return True


needs_ray = pytest.mark.skipif(not _has_ray(), reason="the optional 'ray' extra is not installed "
                                                      "(pip install 'rsart[ray]')")


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")])
    env.setdefault("RAY_AUTH_MODE", "disabled")
    return env


def _cmd(data: Path, out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "pd2gs", "run", "--data", str(data), "--out", str(out), *FAST, *extra]


def _run(data: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    r = subprocess.run(_cmd(data, out, *extra), capture_output=True, text=True, env=_env(), timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def _files(sub: Path) -> dict[str, bytes]:
    return {str(p.relative_to(sub)): p.read_bytes() for p in sorted(sub.rglob("*")) if p.is_file()}


def _assert_same_submission(a: Path, b: Path) -> None:
    fa, fb = _files(a), _files(b)
    assert sorted(fa) == sorted(fb)
    assert any(k.endswith(".ply") for k in fa), "the objects should have meshes to compare"
    for k in fa:
        assert fa[k] == fb[k], f"{k} differs"


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    from rsart.cli import main as rsart_main
    from rsart.sources.procedural.registry import generate
    from rsart.twin_io import write_object

    root = tmp_path_factory.mktemp("runner")
    for cat, seed in (("storage", 1), ("drawer", 0)):
        g = generate(cat, seed)
        write_object(g.twin, root / "twins" / g.object_id, object_id=g.object_id, category=g.category,
                     source=g.source)
        assert rsart_main(["render", str(root / "twins" / g.object_id), "--protocol", "pd2gs", "--out",
                           str(root / "data"), "--size", "96x72", "--views", "6", "--test-views", "1",
                           "--background", "plain", "--workers", "1", "--no-progress"]) == 0
    return root / "data"


@pytest.fixture(scope="module")
def reference(data, tmp_path_factory) -> Path:
    """The uninterrupted run on local processes."""
    out = tmp_path_factory.mktemp("reference")
    r = _run(data, out, "--backend", "process", "--workers", "2")
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary["done"]) == ["drawer-0000", "storage-0001"], r.stdout
    for oid in summary["done"]:
        run = out / "runs" / oid
        # FAST's settings are not the defaults: their results have a folder of their own
        assert (run / "metrics.json").is_file() and [p.name for p in (run / "results").iterdir()] == [VARIANT]
        assert (run / "results" / VARIANT / "result.json").is_file()
        assert "attempt on" in (run / "log.txt").read_text()
        obj = json.loads((run / "object.json").read_text())
        assert obj["status"] == "done" and obj["timings"]["train_s"] > 0
    return out / "submission"


def _wait_for_stage(out: Path, proc: subprocess.Popen, stages: tuple[str, ...], timeout: float = 600) -> tuple[str, dict]:
    t0 = time.time()
    while time.time() - t0 < timeout:
        assert proc.poll() is None, "the run ended before the stage was reached"
        for st in sorted(out.glob("runs/*/status.json")):
            try:
                doc = json.loads(st.read_text())
            except (OSError, json.JSONDecodeError):
                continue
            if doc.get("stage") in stages:
                return st.parent.name, doc
        time.sleep(0.2)
    raise AssertionError(f"no object reached {stages} in {timeout} s")


@pytest.mark.slow
def test_rerun_skips_finished_objects(data, reference):
    out = reference.parent
    before = (reference / "submission.json").stat().st_mtime_ns
    r = _run(data, out, "--backend", "process")
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary["skipped"]) == ["drawer-0000", "storage-0001"] and not summary["done"]
    assert "skipped 2" in r.stdout
    assert (reference / "submission.json").stat().st_mtime_ns != before  # reassembled, same bytes
    for oid in summary["skipped"]:
        assert (out / "runs" / oid / "log.txt").read_text().count("attempt on") == 1


@pytest.mark.slow
def test_a_run_with_other_settings_keeps_the_finished_results(data, reference, tmp_path):
    """`pd2gs run --joint-rule bic` into an --out that holds a finished run: the training is reused, the
    new discovery gets its own result folder, and the first run's results are left as they were."""
    import shutil

    out = tmp_path / "out"
    shutil.copytree(reference.parent, out)
    first = {oid: (out / "runs" / oid / "results" / VARIANT / "result.json").read_bytes()
             for oid in ("drawer-0000", "storage-0001")}
    _run(data, out, "--backend", "process", "--joint-rule", "bic")
    other = _variant(mode="paper", refine=False, joint_rule="bic")
    assert other != VARIANT and other.startswith("settings-")
    for oid, before in first.items():
        results = out / "runs" / oid / "results"
        assert sorted(p.name for p in results.iterdir()) == sorted([VARIANT, other])
        assert (results / VARIANT / "result.json").read_bytes() == before
        doc = json.loads((results / other / "result.json").read_text())
        assert doc["discovery"]["joint_rule"] == "bic" and doc["status"] == "done"
        assert (out / "runs" / oid / "log.txt").read_text().count("attempt on") == 2  # trained once: reused
    sub = json.loads((out / "submission" / "submission.json").read_text())
    assert sub["method"]["discovery"]["joint_rule"] == "bic"  # the submission is this command's


def test_variant_names_follow_the_discovery_settings():
    assert _variant() == "default"
    assert _variant(background=(1.0, 1.0, 1.0)) == "default"  # the trained field's background: same results
    staged = _variant(fit_ownership="staged")
    assert staged.startswith("settings-") and len(staged) == len("settings-") + 10
    assert staged == _variant(fit_ownership="staged") != _variant(fit_ownership="frozen")


@pytest.mark.slow
@needs_ray
def test_ray_backend_writes_the_same_submission_as_processes(data, reference, tmp_path):
    r = _run(data, tmp_path / "ray", "--backend", "ray", "--workers", "2")
    assert "done 2, failed 0" in r.stdout
    _assert_same_submission(reference, tmp_path / "ray" / "submission")


@pytest.mark.slow
@needs_ray
def test_killed_ray_worker_is_retried_and_the_submission_is_the_same(data, reference, tmp_path):
    out = tmp_path / "killed"
    proc = subprocess.Popen(_cmd(data, out, "--backend", "ray", "--workers", "2"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env())
    try:
        oid, doc = _wait_for_stage(out, proc, ("train",))
        os.kill(doc["pid"], signal.SIGKILL)  # the Ray worker process running this object
        stdout, stderr = proc.communicate(timeout=900)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr[-3000:]
    log = (out / "runs" / oid / "log.txt").read_text()
    assert log.count("attempt on") == 2, log  # the killed attempt, then Ray's retry
    assert "done 2, failed 0" in stdout
    _assert_same_submission(reference, out / "submission")


@pytest.mark.slow
def test_killed_process_worker_is_retried_and_the_submission_is_the_same(data, reference, tmp_path):
    out = tmp_path / "killed-process"
    proc = subprocess.Popen(_cmd(data, out, "--backend", "process", "--workers", "2"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env())
    try:
        oid, doc = _wait_for_stage(out, proc, ("train",))
        os.kill(doc["pid"], signal.SIGKILL)  # one worker process of the pool
        stdout, stderr = proc.communicate(timeout=900)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr[-3000:]
    assert "worker process died; retrying" in stderr
    assert (out / "runs" / oid / "log.txt").read_text().count("attempt on") == 2
    assert "done 2, failed 0" in stdout
    _assert_same_submission(reference, out / "submission")


def _stop(proc: subprocess.Popen, sig: int) -> str:
    """Send ``sig`` to the running driver and wait for it; -> its stderr, once it ended as an interrupt does
    (exit 130, a one-line message, no traceback). The caller kills it in a ``finally`` if it did not end."""
    proc.send_signal(sig)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr[-2000:]
    assert "interrupted" in stderr and "Traceback" not in stderr
    return stderr


@pytest.mark.slow
def test_interrupted_run_resumes_to_the_same_submission(data, reference, tmp_path):
    out = tmp_path / "interrupted"
    # a test run started in the background by a non-interactive shell inherits SIGINT ignored, and so would
    # the run under test: Ctrl-C must reach it as at a terminal
    proc = subprocess.Popen(_cmd(data, out, "--backend", "process", "--workers", "1"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        t0 = time.time()
        while not list(out.glob("runs/*/metrics.json")):  # the first object's training stage is finished
            assert proc.poll() is None and time.time() - t0 < 600
            time.sleep(0.2)
        _stop(proc, signal.SIGINT)  # Ctrl-C
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not (out / "submission").exists()
    trained = [p.parent.name for p in out.glob("runs/*/metrics.json")]
    r = _run(data, out, "--backend", "process", "--workers", "1")
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["done"]) + len(summary["skipped"]) == 2 and not summary["failed"], r.stdout
    first = trained[0]
    log = (out / "runs" / first / "log.txt").read_text()
    assert first in summary["skipped"] or "reusing the finished run" in log, log  # its training is not redone
    assert log.count("training: 40 iterations") == 1
    _assert_same_submission(reference, out / "submission")


def _alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie no reaper collected counts as ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


@pytest.mark.slow
def test_terminated_run_stops_its_workers(data, tmp_path):
    """SIGTERM (``kill``) to the driver ends the run as Ctrl-C does: its workers stop with it instead of
    running on, orphaned, into the run folders."""
    out = tmp_path / "terminated"
    proc = subprocess.Popen(_cmd(data, out, "--backend", "process", "--workers", "2"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env())
    try:
        _, doc = _wait_for_stage(out, proc, ("train",))
        worker = doc["pid"]
        assert worker != proc.pid and _alive(worker)
        _stop(proc, signal.SIGTERM)  # kill
    finally:
        if proc.poll() is None:
            proc.kill()
    t0 = time.time()
    while _alive(worker) and time.time() - t0 < 30:
        time.sleep(0.2)
    assert not _alive(worker), f"worker {worker} still runs after its driver was terminated"


def test_ray_backend_without_ray_says_how_to_install_it(tmp_path):
    fake = tmp_path / "noray" / "ray"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('No module named ray')\n")
    env = _env()
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path / "noray"), env["PYTHONPATH"]])
    r = subprocess.run([sys.executable, "-m", "pd2gs", "run", "--data", str(tmp_path), "--out",
                        str(tmp_path / "out"), "--backend", "ray"], capture_output=True, text=True, env=env)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'rsart[ray]'" in lines[0], r.stderr
    assert not (tmp_path / "out").exists()


def test_bad_runner_options_exit_2(tmp_path):
    for extra, msg in ((["--workers", "0"], "--workers"), (["--threads", "0"], "--threads"),
                       (["--address", "1.2.3.4:6379"], "--address needs --backend ray")):
        r = subprocess.run([sys.executable, "-m", "pd2gs", "run", "--data", str(tmp_path), "--out",
                            str(tmp_path / "out"), *extra], capture_output=True, text=True, env=_env())
        assert r.returncode == 2 and msg in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_mesh_bytes_do_not_depend_on_vertex_and_face_order():
    from pd2gs.discovery.submission import _ply

    m = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(0)
    perm = rng.permutation(len(m.vertices))
    inv = np.argsort(perm)
    faces = inv[m.faces][rng.permutation(len(m.faces))]
    faces = np.roll(faces, 1, axis=1)  # the same triangles, each starting at another corner
    shuffled = trimesh.Trimesh(m.vertices[perm], faces, process=False)
    assert _ply(shuffled) == _ply(m)
    back = trimesh.load(trimesh.util.wrap_as_stream(_ply(shuffled)), file_type="ply", process=False)
    assert np.isclose(back.volume, m.volume) and np.allclose(back.face_normals.sum(0), m.face_normals.sum(0))


@pytest.mark.slow
def test_runner_benchmark_script_runs(tmp_path):
    out = tmp_path / "bench.md"
    r = subprocess.run([sys.executable, str(REPO / "benchmarks" / "pd2gs_runner.py"), "--work", str(tmp_path / "w"),
                        "--objects", "2", "--iters", "40", "--size", "128x96", "--views", "6", "--workers", "1,2",
                        "--discovery", "fast", "--threads", "1", "--out", str(out)],
                       capture_output=True, text=True, env=_env(), timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert [row["workers"] for row in rows] == [1, 2]
    assert all(row["done"] == 2 for row in rows), (rows, r.stdout[-2000:])
    assert all(row["wall_s"] > 0 for row in rows)
    text = out.read_text()
    assert "| 1 |" in text and "| 2 |" in text and "speed-up" in text


def test_a_stored_discovery_is_reused_only_when_the_same_code_made_it(tmp_path):
    """Results keyed by settings alone once let a benchmark rescore discoveries made before a change to
    model selection beside ones made after it."""
    from pd2gs.discovery.config import DiscoveryConfig
    from pd2gs.runner import _norm, code_id, finished_result

    cfg = DiscoveryConfig()
    res_dir = tmp_path / "results" / "default"
    res_dir.mkdir(parents=True)
    doc = {"status": "done", "discovery": _norm(dataclasses.asdict(cfg))}
    for code, reused in ((code_id(), True), ("0" * 16, False), (None, False)):
        (res_dir / "result.json").write_text(json.dumps({**doc, **({"code": code} if code else {})}))
        assert (finished_result(tmp_path, "default", cfg) is not None) is reused, code
    assert len(code_id()) == 16 and code_id() == code_id()
