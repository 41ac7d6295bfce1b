"""Open any RealSense recording: picks the reader for a path (frame folder, colour video, ``.bag``).

Its own module so that :mod:`capture_tools.readers` (the base classes and the folder/video readers)
and :mod:`capture_tools.bag` (the optional ``rosbags`` reader, built on those base classes) do not
import each other.
"""
from __future__ import annotations

from pathlib import Path

from .bag import BagRecording
from .readers import VIDEO_EXT, CaptureError, FrameFolderRecording, Recording, VideoRecording


def open_recording(path: str | Path) -> Recording:
    """The reader for ``path``: a ``.bag`` file, a video file, or a folder (frame folder, or a folder whose
    colour is a single video ``color.mp4``/``.avi``/``.mkv``/``.mov``)."""
    p = Path(path)
    if p.is_file() and p.suffix.lower() == ".bag":
        return BagRecording(p)
    if p.is_file() and p.suffix.lower() in VIDEO_EXT:
        return VideoRecording(p)
    if p.is_dir():
        if (p / "color").is_dir():
            return FrameFolderRecording(p)
        vids = sorted(q for q in p.iterdir() if q.stem == "color" and q.suffix.lower() in VIDEO_EXT)
        if vids:
            return VideoRecording(vids[0])
        bags = sorted(p.glob("*.bag"))
        if len(bags) == 1:
            return BagRecording(bags[0])
        raise CaptureError(f"{p}: no color/ folder, color video or single .bag recording found")
    raise CaptureError(f"{p}: not a recording (expected a folder, a video file or a .bag)")
