"""``rsart_export.json``: what an export holds (method, protocol, object, runs, states, frame, views),
written beside the method's files so a run can be traced back to its rsart object.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from rsart.io import atomic_write_text, write_json

MANIFEST = "rsart_export.json"
FORMAT = "rsart-export/1"


def write_manifest(folder: Path, *, method: str, object_id: str, object_dir: Path, protocol: str, frame: str,
                   runs: dict[str, dict[str, Any]], extra: dict[str, Any] | None = None) -> None:
    write_json(folder / MANIFEST, {"format": FORMAT, "method": method, "object_id": object_id,
                                   "object_dir": str(object_dir.resolve()), "protocol": protocol,
                                   "frame": frame, "runs": runs, **(extra or {})})


def write_readme(folder: Path, text: str) -> None:
    atomic_write_text(folder / "README.txt", text.rstrip() + "\n")
