"""``pd2gs run``: train -> discover parts -> kinematics -> meshes -> an rsart-submission/1, per object.

Glue between the trainer (:mod:`pd2gs.train`) and part discovery (:mod:`pd2gs.discovery`); an object
that fails anywhere becomes ``null`` in the submission with its reason logged, never a crash.
"""
from __future__ import annotations

import logging
from pathlib import Path

from rsart.errors import RsartError

log = logging.getLogger(__name__)


def select_objects(data: str | Path, objects: list[str] | None = None, split: str | None = None) -> list:
    """The RSArtObjects to run: ``data`` is one object folder, or a dataset (all objects, a split, or ids)."""
    import rsart

    d = rsart.load(Path(data))
    if isinstance(d, rsart.RSArtObject):
        return [d]
    if split is not None and split not in d.splits:
        raise RsartError(f"{data}: unknown split {split!r} (index.json has {sorted(d.splits)})")
    ids = objects or (d.splits[split] if split else list(d))
    unknown = [i for i in ids if i not in d]
    if unknown:
        raise RsartError(f"{data}: unknown objects {unknown}")
    return [d[i] for i in ids]


def run(data: str | Path, out: str | Path, objects: list[str] | None = None, split: str | None = None,
        train_cfg=None, discovery_cfg=None, progress: bool = True, backend: str = "process",
        workers: int | None = None, address: str | None = None, threads: int | None = None) -> Path:
    """Run PD²GS on every object (of ``split`` / ``objects``) under ``data``; write ``out/submission/``.

    One task per object (:mod:`pd2gs.runner`: ``backend`` "process" with ``workers`` local processes, or
    "ray" on the cluster at ``address`` / a local Ray), ``threads`` CPU threads each (default: this
    machine's cores / workers; 1 on a Ray cluster). Training runs and per-object results go to
    ``out/runs/<object_id>/`` (a re-run skips finished objects and reuses finished stages); the
    submission (meshes + ``submission.json``, scored by ``rsart-eval``) to ``out/submission/``, and the
    done / failed / skipped summary to ``out/summary.json``. Returns the submission.json path.
    """
    from .discovery.config import DiscoveryConfig
    from .discovery.pipeline import dataset_block, method_block
    from .runner import ObjectTask, assemble, default_threads, execute, import_ray, summarize, variant_name
    from .train import TrainConfig

    if backend == "ray":
        import_ray()  # before anything else: without ray, say how to install it
    data, out = Path(data), Path(out)
    objs = select_objects(data, objects, split)
    dcfg = discovery_cfg or DiscoveryConfig()
    tcfg = train_cfg or TrainConfig()
    if threads is None:
        threads = 1 if (backend == "ray" and address) else default_threads(workers or 1)
    if threads < 1:
        raise RsartError(f"threads must be at least 1, got {threads}")
    # one result folder per discovery setting: other settings never replace a finished default result
    name = variant_name(dcfg)
    if name != "default":
        log.info("discovery settings differ from the defaults: results go to runs/<object_id>/results/%s/", name)
    # absolute paths: a worker (a Ray node) need not share this process's working directory
    tasks = [ObjectTask(str(data.resolve()), o.id, str(out.resolve() / "runs" / o.id), tcfg, {name: dcfg},
                        threads) for o in objs]
    outcomes = execute(tasks, backend, workers, address, progress)
    n_states = dcfg.n_states or len(tcfg.states or [s for s in objs[0].meta.states if s.kind == "multi"])
    sub = assemble(tasks, name, outcomes, out / "submission", method_block(dcfg, n_states),
                   dataset_block(str(data)))
    summarize(outcomes, out / "summary.json")
    return sub
