"""Run one step of discovery on several runs at once, each in its own child process.

Discovery's starts are independent, and a fit that renders one 120 px view per step does not double its speed
with a second thread (a start on one thread takes 1.4-1.5x its time on two; `benchmarks/results/
discovery-side-by-side-zen3.md`), so on a machine with two or more threads the starts are fitted side by side,
the threads shared out, instead of one after another on all of them.

Children are plain ``python -m pd2gs.discovery.side_by_side`` processes: multiprocessing's ``spawn`` would
re-import the caller's main script in every child (a script without ``if __name__ == "__main__":`` would run
again), and ``fork`` would hand the children the parent's OpenMP and Numba thread pools, which are not
fork-safe. The step (a module-level function, pickled by name, so the child imports its module) and the run go
to the child as a pickle on stdin, the run comes back on stdout; nothing is written to disk. The children's
thread count comes from the environment (``OMP_NUM_THREADS``, ``NUMBA_NUM_THREADS``, read at import).

    python -m pd2gs.discovery.side_by_side < (step, run).pickle > run.pickle   (the child's entry)
"""
from __future__ import annotations

import io
import logging
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

import torch

log = logging.getLogger(__name__)


def run_side_by_side(step: Callable[[Any], None], runs: list[Any], threads: int, at_once: int) -> list[Any] | None:
    """``step(run)`` (a module-level function that changes its run in place) on every run, each in a child
    process with ``threads`` CPU threads, ``at_once`` children at a time -> the runs as the children left them
    (same order), or None when a child failed (its stderr is logged; the caller then runs the step itself,
    which raises the real error if there is one)."""
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
        env[var] = str(threads)

    def child(run: Any) -> tuple[int, bytes, bytes]:
        buf = io.BytesIO()
        torch.save((step, run), buf)
        p = subprocess.Popen([sys.executable, "-m", __name__], env=env, stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        out, err = p.communicate(buf.getvalue())
        return p.returncode, out, err

    with ThreadPoolExecutor(max(1, at_once)) as ex:  # each thread starts one child, feeds and drains its pipes
        outs = list(ex.map(child, runs))
    failed = [f"child {i} exited {rc}: {err.decode(errors='replace')[-2000:]}"
              for i, (rc, _, err) in enumerate(outs) if rc != 0]
    if failed:
        log.warning("%s side by side failed; running it one run after another\n%s", getattr(step, "__name__", step),
                    "\n".join(failed))
        return None
    # the children's pickles, made by this module from runs this process sent them
    return [torch.load(io.BytesIO(out), weights_only=False) for _, out, _ in outs]


def _child() -> int:
    result = os.fdopen(os.dup(1), "wb")  # the pickle goes here; anything else printed to stdout goes to stderr
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    step, run = torch.load(io.BytesIO(sys.stdin.buffer.read()), weights_only=False)  # sent by run_side_by_side
    step(run)
    buf = io.BytesIO()
    torch.save(run, buf)
    result.write(buf.getvalue())
    result.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(_child())
