"""Write a rendered object folder back out as a *raw* capture (poses withheld), in each recording layout.

This is how the simulator's booth captures become test input for the capture tools: every state of
``object_dir`` becomes one recording under ``raw_dir`` -- a frame folder, a colour video + depth
folder, or a RealSense-style .bag -- plus ``raw_dir/states.yaml``, the capture log (state ids, kinds,
joint values, recording paths). Camera poses, masks and clean images are *not* written.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml

from rsart.errors import RsartError
from rsart.format import read_cameras, read_meta
from rsart.io import atomic_write_text, read_depth_png, read_png_rgb

from .readers import StreamCalibration, write_calibration

LAYOUTS = ("frames", "video", "bag")
VIDEO_CODECS = {"FFV1": "color.mkv", "MJPG": "color.avi"}


def _depth_units(path: Path, scale: float) -> np.ndarray:
    return np.round(read_depth_png(path, scale) / scale).astype(np.uint16)


def write_raw_capture(object_dir: str | Path, raw_dir: str | Path, layout: str = "frames",
                      states: list[str] | None = None, fps: float = 30.0, codec: str = "FFV1") -> Path:
    """Write the rendered ``states`` (default: all captured) of ``object_dir`` to ``raw_dir``; returns states.yaml.

    ``codec`` (video layout): "FFV1" (lossless, ``color.mkv``) or "MJPG" (lossy, ``color.avi``).
    """
    if codec not in VIDEO_CODECS:
        raise RsartError(f"video codec {codec!r} is not one of {sorted(VIDEO_CODECS)}")
    if layout not in LAYOUTS:
        raise RsartError(f"layout {layout!r} is not one of {LAYOUTS}")
    obj, raw = Path(object_dir), Path(raw_dir)
    meta = read_meta(obj)
    ids = states or [s.id for s in meta.states if (obj / "states" / s.id / "cameras.json").is_file()]
    log = {"object_id": meta.object_id, "category": meta.category, "units": meta.units,
           "eval_states": dict(meta.eval_states), "states": []}
    for sid in ids:
        st = meta.state(sid)
        sdir = obj / "states" / sid
        cams = read_cameras(sdir / "cameras.json")
        cal = StreamCalibration(cams.intrinsics, cams.depth_scale)
        views = [v.id for v in cams.views]
        if layout == "bag":
            from .bag import write_realsense_bag

            frames = [(i / fps, read_png_rgb(sdir / "rgb" / f"{v}.png")[..., :3],
                       _depth_units(sdir / "depth" / f"{v}.png", cams.depth_scale)) for i, v in enumerate(views)]
            rec = f"{sid}.bag"
            raw.mkdir(parents=True, exist_ok=True)
            write_realsense_bag(raw / rec, frames, cams.intrinsics, cams.depth_scale)
        else:
            rec = sid
            out = raw / sid
            (out / "depth").mkdir(parents=True, exist_ok=True)
            write_calibration(out / "intrinsics.json", cal)
            writer = None
            if layout == "frames":
                (out / "color").mkdir(exist_ok=True)
            else:
                intr = cams.intrinsics
                vpath = out / VIDEO_CODECS[codec]
                writer = cv2.VideoWriter(str(vpath), cv2.VideoWriter_fourcc(*codec), fps, (intr.width, intr.height))
                if not writer.isOpened():
                    raise RsartError(f"{vpath}: OpenCV cannot write {codec} video here")
            lines = ["name,timestamp_ms"]
            for i, v in enumerate(views):
                rgb = read_png_rgb(sdir / "rgb" / f"{v}.png")[..., :3]
                name = f"{i:06d}"
                if writer is None:
                    cv2.imwrite(str(out / "color" / f"{name}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
                else:
                    writer.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
                cv2.imwrite(str(out / "depth" / f"{name}.png"), _depth_units(sdir / "depth" / f"{v}.png", cams.depth_scale))
                lines.append(f"{name},{1000.0 * i / fps:.3f}")
            if writer is not None:
                writer.release()
            atomic_write_text(out / "timestamps.csv", "\n".join(lines) + "\n")
        entry = {"id": sid, "kind": st.kind, "values": {k: float(x) for k, x in st.values.items()}, "recording": rec}
        if st.kind == "single":
            entry.update(joint=st.joint, extreme=st.extreme)
        log["states"].append(entry)
    if not set(log["eval_states"].values()) <= set(ids):
        del log["eval_states"]  # a subset of the states: the assembler picks the first and last multi state
    path = raw / "states.yaml"
    atomic_write_text(path, yaml.safe_dump(log, sort_keys=False))
    return path
