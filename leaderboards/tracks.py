"""Tracks: comparable groups of submissions, derived from the submission's free-form ``method`` block.

* ``camera_poses``: ``gt`` | ``estimated`` (``method.camera_poses``; any value other than ``gt``, e.g.
  ``colmap``, counts as estimated);
* ``states``: ``2`` | ``N`` (``method.states_used``: 2 → ``2``; more, or ``"all"`` → ``N``);
* ``part_count``: ``given`` | ``inferred`` (``method.part_count``; else ``method.discovery.counter ==
  "given"``; ground-truth reference submissions are ``given``);
* ``inputs``: ``rgb`` | ``rgbd`` (``method.inputs`` containing ``depth``/``rgbd`` → ``rgbd``).

A field the block does not state is ``unspecified``; it is shown, never guessed.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

UNSPECIFIED = "unspecified"
TRACK_FIELDS = ("camera_poses", "states", "part_count", "inputs")


@dataclass(frozen=True)
class Track:
    camera_poses: str
    states: str
    part_count: str
    inputs: str

    def key(self) -> str:
        """Short id, e.g. ``poses-gt_states-N_parts-inferred_rgb``."""
        return f"poses-{self.camera_poses}_states-{self.states}_parts-{self.part_count}_{self.inputs}"

    def label(self) -> str:
        return (f"poses {self.camera_poses} · {self.states} states · parts {self.part_count} · "
                f"{self.inputs.upper() if self.inputs != UNSPECIFIED else 'inputs ' + UNSPECIFIED}")

    def to_dict(self) -> dict[str, str]:
        return asdict(self)


def _poses(m: dict) -> str:
    v = m.get("camera_poses")
    if not isinstance(v, str) or not v:
        return UNSPECIFIED
    return "gt" if v.lower() in ("gt", "ground-truth", "ground_truth") else "estimated"


def _states(m: dict) -> str:
    v = m.get("states_used")
    if isinstance(v, bool) or v is None:
        return UNSPECIFIED
    if isinstance(v, int):
        return "2" if v <= 2 else "N"
    if isinstance(v, str):
        return "N" if v.lower() in ("all", "n", "multi") else ("2" if v.strip() == "2" else UNSPECIFIED)
    return UNSPECIFIED


def _inputs(m: dict) -> tuple[str, bool]:
    v = m.get("inputs")
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v:
        return UNSPECIFIED, False
    low = [str(x).lower() for x in v]
    gt = any("ground-truth" in x for x in low)
    if any(("depth" in x) or (x == "rgbd") or ("rgb-d" in x) for x in low):
        return "rgbd", gt
    if any("rgb" in x for x in low):
        return "rgb", gt
    return ("gt" if gt else UNSPECIFIED), gt


def _part_count(m: dict, ground_truth: bool) -> str:
    v = m.get("part_count")
    if isinstance(v, str) and v.lower() in ("given", "inferred"):
        return v.lower()
    disc = m.get("discovery")
    if isinstance(disc, dict) and isinstance(disc.get("counter"), str):
        return "given" if disc["counter"] == "given" else "inferred"
    return "given" if ground_truth else UNSPECIFIED


def derive_track(method: Any) -> Track:
    """The track of a submission's ``method`` block (a dict; anything else → all ``unspecified``)."""
    m = method if isinstance(method, dict) else {}
    inputs, gt = _inputs(m)
    return Track(_poses(m), _states(m), _part_count(m, gt), inputs)
