"""Small rendered objects (cabinet: revolute lid + prismatic drawer; lamp: chained revolute joints),
rendered by rsart.render with the two-state and single-joint protocols (few tiny views: fast), and
helpers to score a submission with rsart.evaluation."""
from __future__ import annotations

from pathlib import Path

import pytest

from rsart.camera import Intrinsics
from rsart.twin_io import write_object

from tests.baselines_adapters.ba_helpers import score
from tests.conftest import make_cabinet, make_lamp

SIZE = (64, 48)


def _render(obj_dir: Path, protocol: str) -> Path:
    from rsart.render.frame import RenderOptions
    from rsart.render.runner import RenderJob, render_object_dir

    job = RenderJob(protocol=protocol, views=3, test_views=1,
                    options=RenderOptions(intrinsics=Intrinsics.from_fov(SIZE[0], SIZE[1], 50.0), rgb_backend="raycast"))
    render_object_dir(obj_dir, job, workers=1, progress=False)
    return obj_dir


def _object(root: Path, twin, oid: str, protocol: str) -> Path:
    out = root / protocol / oid
    write_object(twin, out, object_id=oid, category="test", source={"kind": "procedural", "id": "test"})
    return _render(out, protocol)


@pytest.fixture(scope="session")
def objects(tmp_path_factory) -> dict[str, Path]:
    """{"cabinet/two-state", "cabinet/single-joint", "lamp/single-joint"} -> object folders."""
    root = tmp_path_factory.mktemp("objects")
    return {"cabinet/two-state": _object(root, make_cabinet(), "cabinet-0000", "two-state"),
            "cabinet/single-joint": _object(root, make_cabinet(), "cabinet-0000", "single-joint"),
            "lamp/single-joint": _object(root, make_lamp(), "lamp-0000", "single-joint")}


@pytest.fixture(scope="session")
def gt_scores(tmp_path_factory, objects) -> dict[str, dict]:
    """The ground-truth reference submission's scores per object folder key (the Chamfer sampling floor),
    computed on first use of each key."""
    from rsart.evaluation import load_ground_truth, make_gt_submission

    root = tmp_path_factory.mktemp("gt-subs")

    class Lazy(dict):
        def __missing__(self, key: str) -> dict:
            d = objects[key]
            self[key] = score(make_gt_submission(load_ground_truth(d), root / key.replace("/", "_")), d)
            return self[key]

    return Lazy()
