"""A small ground-truth dataset (two storage cabinets, one chained lamp) and its GT submission."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from rsart.format import DatasetIndex, write_index
from rsart.twin_io import write_object


def build_dataset(root: Path, cabinet, lamp) -> Path:
    """Objects written with rsart's own writer from the shared test twins (tests/conftest.py)."""
    ids = {"cabinet-0000": ("storage", cabinet), "cabinet-0001": ("storage", cabinet), "lamp-0000": ("lamp", lamp)}
    for oid, (cat, twin) in ids.items():
        write_object(twin, root / oid, object_id=oid, category=cat, source={"kind": "procedural", "id": oid},
                     write_usd=False)
    write_index(DatasetIndex("tiny", "1", list(ids), {"test": list(ids), "lamps": ["lamp-0000"]}), root)
    return root


@pytest.fixture
def dataset(tmp_path, cabinet, lamp) -> Path:
    return build_dataset(tmp_path / "data" / "tiny", cabinet, lamp)


@pytest.fixture
def gt_submission_dir(dataset, tmp_path) -> Path:
    from rsart.evaluation import load_ground_truth, make_gt_submission

    out = tmp_path / "gtsub" / "gt"
    make_gt_submission(load_ground_truth(dataset), out)
    return out


@pytest.fixture
def sub_copy(gt_submission_dir, tmp_path):
    """A fresh editable copy of the GT submission: returns (folder, dict, save())."""
    d = tmp_path / "sub"
    shutil.copytree(gt_submission_dir, d)
    data = json.loads((d / "submission.json").read_text())

    def save(obj=None):
        (d / "submission.json").write_text(json.dumps(data if obj is None else obj))
        return d / "submission.json"

    return d, data, save
