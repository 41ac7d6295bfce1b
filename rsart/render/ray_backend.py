"""Optional Ray backend: distribute render tasks over a Ray cluster (``pip install ray``).

Each task is one chunk of one (object, state); every Ray worker process keeps its scene between
chunks of the same state, as the process pool does. Workers write into the object folder, so
the output root must be on storage every node can reach (shared filesystem).
"""
from __future__ import annotations

from typing import Iterator

from ..errors import RsartError
from .worker import init_worker, render_task


def run_on_ray(tasks: list, address: str | None = None, workers: int | None = None) -> Iterator[int]:
    """Yield the number of views written as each task finishes. Starts a local Ray unless ``address``."""
    try:
        import ray
    except ImportError:
        raise RsartError("--backend ray needs the optional 'ray' package (pip install ray)") from None

    started = False
    if not ray.is_initialized():
        kwargs = {"address": address} if address else {"num_cpus": workers} if workers else {}
        ray.init(ignore_reinit_error=True, log_to_driver=False, **kwargs)
        started = True

    @ray.remote(num_cpus=1)
    def _run(task) -> int:
        init_worker(1)
        return render_task(task)

    try:
        pending = [_run.remote(t) for t in tasks]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for r in ready:
                yield int(ray.get(r))
    finally:
        if started:
            ray.shutdown()
