"""What every adapter is: an exporter (rsart object -> a method's input folder) and an importer (a
method's output folder -> one entry of an ``rsart-submission/1`` file).

An adapter is any object with the attributes and methods of :class:`Adapter`; the ``rsart`` CLI finds
adapters through the entry-point group ``rsart.adapters`` (name = method name, value = an
``Adapter`` instance, or a class / zero-argument factory returning one), so a third party adds a
method without touching rsart. The built-in adapters subclass :class:`Adapter` for the shared
plumbing: locating the object, choosing the protocol's rendered states, and reporting.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import __version__

PROTOCOL_VIEWS = 100  # training views per state in the paper's protocol for these baselines


@dataclass
class ExportReport:
    """What an export wrote: ``out`` folder, ``protocol``, per run the state ids used, notes/warnings."""

    method: str
    object_id: str
    out: Path
    protocol: str
    runs: dict[str, dict[str, str]]          # run name -> {"start": state id, "end": state id}
    views: dict[str, int] = field(default_factory=dict)   # state id -> exported views
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        lines = [f"{self.method}: exported {self.object_id} ({self.protocol} protocol) to {self.out}"]
        for name, st in self.runs.items():
            lines.append(f"  run {name}: start={st['start']} end={st['end']}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


@dataclass
class ImportReport:
    """What an import did: the submission written, the object entry's parts, and the adapter's notes."""

    method: str
    object_id: str
    submission: Path
    parts: list[str]
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        lines = [f"{self.method}: imported {self.object_id} into {self.submission} (parts: {', '.join(self.parts)})"]
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def render_hint(object_dir: Path, protocol: str) -> str:
    """The exact command that renders the states an export needs."""
    return (f"rsart render {object_dir} --protocol {protocol} --out {object_dir.parent}-{protocol}"
            f"  (then export from {object_dir.parent}-{protocol}/{object_dir.name})")


class Adapter:
    """Base of the built-in adapters. Subclasses set the class attributes and implement
    :meth:`export` and :meth:`import_run`.

    ``name``: CLI method name; ``title``: the method as papers cite it; ``protocol``: "two-state" or
    "single-joint" (the capture protocol of rsart.render.protocols the paper used for this family);
    ``inputs``: what the method consumes (recorded in the submission's ``method.inputs``).
    """

    name: str = ""
    title: str = ""
    protocol: str = "two-state"
    inputs: tuple[str, ...] = ("rgb",)
    description: str = ""
    run_layout: str = ""

    version = __version__

    def export(self, object_dir: Path, out_dir: Path, *, frame: str = "z-up", overwrite: bool = False,
               **options: Any) -> ExportReport:
        raise NotImplementedError

    def import_run(self, run_dir: Path, object_dir: Path, submission: Path, *, frame: str = "z-up",
                   method_version: str | None = None, **options: Any) -> ImportReport:
        raise NotImplementedError

    def record_failure(self, submission: Path, object_id: str, reason: str, *, method_version: str | None = None,
                       dataset: dict | None = None) -> Path:
        """Mark ``object_id`` as failed (``null`` entry) in ``submission``."""
        from .submission_io import write_failure

        return write_failure(Path(submission), object_id, self.method_record(method_version), reason, dataset)

    def method_record(self, method_version: str | None) -> dict[str, Any]:
        """The submission's ``method`` block for this adapter."""
        return {"name": self.title or self.name, "version": method_version or "unknown",
                "inputs": list(self.inputs), "camera_poses": "gt", "states_used": 2,
                "protocol": self.protocol, "adapter": f"baselines_adapters.{self.name} {self.version}"}

    def __repr__(self) -> str:
        return f"<adapter {self.name}: {self.title}, {self.protocol}>"

