"""Readers of RealSense recordings: frame folders, colour video + depth folder, ROS1 .bag (rosbags).

Round trips compare every pixel with what was written; the error cases each expect their own error type
and a message naming the file."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from capture_tools.align import align_depth_to_colour
from capture_tools.bag import BagRecording, write_realsense_bag
from capture_tools.readers import (FrameFolderRecording, MissingIntrinsicsError, StreamCalibration,
                                   StreamMismatchError, TruncatedFileError, VideoRecording, write_calibration)
from capture_tools.recording import open_recording
from rsart.camera import Intrinsics

K = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
N = 5


def frames(n=N, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        rgb = rng.integers(0, 256, size=(K.height, K.width, 3), dtype=np.uint8)
        rgb = cv2.GaussianBlur(rgb, (0, 0), 3)  # smooth enough to survive MJPG (lossy, chroma subsampled)
        depth = rng.integers(300, 3000, size=(K.height, K.width)).astype(np.uint16)
        depth[rng.uniform(size=depth.shape) < 0.1] = 0
        out.append((i / 30.0, rgb, depth))
    return out


def write_folder(root, fr, video=False, scale=0.001):
    root.mkdir(parents=True, exist_ok=True)
    write_calibration(root / "intrinsics.json", StreamCalibration(K, scale))
    (root / "depth").mkdir()
    if video:
        w = cv2.VideoWriter(str(root / "color.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30, (K.width, K.height))
    else:
        (root / "color").mkdir()
    for i, (t, rgb, d) in enumerate(fr):
        if video:
            w.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        else:
            cv2.imwrite(str(root / "color" / f"{i:06d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(root / "depth" / f"{i:06d}.png"), d)
    if video:
        w.release()
    return root


def test_frame_folder_round_trip(tmp_path):
    fr = frames()
    rec = open_recording(write_folder(tmp_path / "rec", fr))
    assert isinstance(rec, FrameFolderRecording) and len(rec) == N
    assert rec.intrinsics == K and rec.depth_scale == 0.001
    got = list(rec)
    for (t, rgb, d), f in zip(fr, got):
        assert np.array_equal(f.rgb, rgb)
        assert np.allclose(f.depth, d.astype(np.float32) * 0.001)
        assert f.timestamp == pytest.approx(t)


def test_frame_folder_reads_lazily(tmp_path):
    """Frames are decoded one at a time: damage to a later file surfaces only when that frame is reached."""
    root = write_folder(tmp_path / "rec", frames())
    it = iter(FrameFolderRecording(root))
    first = next(it)
    assert first.index == 0
    (root / "color" / "000003.png").write_bytes((root / "color" / "000003.png").read_bytes()[:100])
    assert next(it).index == 1 and next(it).index == 2
    with pytest.raises(TruncatedFileError, match="000003.png"):
        next(it)


def test_video_round_trip(tmp_path):
    fr = frames()
    rec = open_recording(write_folder(tmp_path / "rec", fr, video=True))
    assert isinstance(rec, VideoRecording) and len(rec) == N
    for (t, rgb, d), f in zip(fr, rec):
        assert np.abs(f.rgb.astype(int) - rgb).mean() < 6  # MJPG is lossy
        assert np.allclose(f.depth, d * 0.001)


def test_bag_round_trip(tmp_path):
    fr = frames()
    path = tmp_path / "rec.bag"
    write_realsense_bag(path, fr, K, 0.001)
    rec = open_recording(path)
    assert isinstance(rec, BagRecording) and len(rec) == N
    assert rec.intrinsics == K and rec.depth_scale == 0.001
    got = list(rec)
    assert len(got) == N
    for (t, rgb, d), f in zip(fr, got):
        assert np.array_equal(f.rgb, rgb)
        assert np.allclose(f.depth, d * 0.001)
        assert f.timestamp == pytest.approx(t, abs=1e-6)


def step_depth(k: Intrinsics, z_out=1.0, z_in=0.8, half=8) -> np.ndarray:
    """A wall at z_out with a square patch at z_in in the image centre (metres)."""
    d = np.full((k.height, k.width), z_out, np.float32)
    cy, cx = int(k.cy), int(k.cx)
    d[cy - half:cy + half, cx - half:cx + half] = z_in
    return d


def test_unaligned_bag_is_aligned_with_extrinsics(tmp_path):
    """Depth recorded by a camera 50 mm to the side of the colour camera lands where geometry says it must:
    a point (x, y, z) of the depth camera is seen by the colour camera at u = fx (x + tx) / z + cx."""
    kd = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    tx = 0.05
    d2c = np.eye(4)
    d2c[0, 3] = tx
    dm = step_depth(kd)
    units = np.round(dm / 0.001).astype(np.uint16)
    rgb = np.zeros((K.height, K.width, 3), np.uint8)
    path = tmp_path / "unaligned.bag"
    write_realsense_bag(path, [(0.0, rgb, units)], K, 0.001, depth_k=kd, depth_to_colour=d2c)
    rec = BagRecording(path)
    assert rec.calibration.depth_to_colour is not None
    assert np.allclose(rec.calibration.depth_to_colour, d2c, atol=1e-9)
    (f,) = list(rec)
    assert f.depth.shape == (K.height, K.width)
    # the patch centre (x = 0 at z = 0.8 in the depth camera) appears at u = fx * tx / z + cx in colour
    u = int(round(K.fx * tx / 0.8 + K.cx))
    v = int(round(K.cy))
    assert f.depth[v, u] == pytest.approx(0.8, abs=1e-3)
    # the wall (z = 1) just outside the patch's shifted left edge
    left_patch_edge_u = K.fx * ((int(kd.cx) - 8 - kd.cx) / kd.fx * 0.8 + tx) / 0.8 + K.cx
    assert f.depth[v, int(np.floor(left_patch_edge_u)) - 2] == pytest.approx(1.0, abs=1e-3)
    # same function directly: pure translation along z leaves depth offset by tz
    d2c_z = np.eye(4)
    d2c_z[2, 3] = 0.1
    out = align_depth_to_colour(np.full((48, 64), 1.0, np.float32), K, K, d2c_z)
    assert np.median(out[out > 0]) == pytest.approx(1.1, abs=1e-6)


# ----------------------------------------------------------------------------- errors
def test_missing_intrinsics(tmp_path):
    root = write_folder(tmp_path / "rec", frames())
    (root / "intrinsics.json").unlink()
    with pytest.raises(MissingIntrinsicsError, match="intrinsics.json"):
        open_recording(root)
    (root / "intrinsics.json").write_text(json.dumps({"color": {"width": 64, "height": 48, "fx": 60, "fy": 60,
                                                                 "ppx": 31.5, "ppy": 23.5}}))
    with pytest.raises(MissingIntrinsicsError, match="depth_scale"):
        open_recording(root)
    (root / "intrinsics.json").write_text(json.dumps({"color": {"width": 64, "height": 48, "fx": 60, "fy": 60},
                                                      "depth_scale": 0.001}))
    with pytest.raises(MissingIntrinsicsError, match="ppx"):
        open_recording(root)


def test_mismatched_stream_counts(tmp_path):
    root = write_folder(tmp_path / "rec", frames())
    (root / "depth" / "000004.png").unlink()
    with pytest.raises(StreamMismatchError, match="5 colour frames but 4 depth frames"):
        open_recording(root)
    vroot = write_folder(tmp_path / "vid", frames(), video=True)
    (vroot / "depth" / "000000.png").unlink()
    with pytest.raises(StreamMismatchError, match="5 video frames but 4 depth"):
        open_recording(vroot)


def test_wrong_image_size(tmp_path):
    root = write_folder(tmp_path / "rec", frames())
    cv2.imwrite(str(root / "color" / "000001.png"), np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(StreamMismatchError, match="10x10"):
        list(open_recording(root))


def test_truncated_files(tmp_path):
    root = write_folder(tmp_path / "rec", frames())
    p = root / "depth" / "000002.png"
    p.write_bytes(p.read_bytes()[:40])
    with pytest.raises(TruncatedFileError, match="000002.png"):
        list(open_recording(root))
    vroot = write_folder(tmp_path / "vid", frames(), video=True)
    v = vroot / "color.avi"
    v.write_bytes(v.read_bytes()[: v.stat().st_size // 2])
    with pytest.raises((TruncatedFileError, StreamMismatchError), match="color.avi"):
        list(open_recording(vroot))
    bag = tmp_path / "rec.bag"
    write_realsense_bag(bag, frames(), K, 0.001)
    bag.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    with pytest.raises(TruncatedFileError, match="rec.bag"):
        list(open_recording(bag))


def test_bag_without_camera_info(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    path = tmp_path / "noinfo.bag"
    with Writer(path) as w:
        c = w.add_connection("/device_0/sensor_1/Color_0/image/data", "sensor_msgs/msg/Image", typestore=ts)
        hdr = T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="")
        img = T["sensor_msgs/msg/Image"](header=hdr, height=2, width=2, encoding="rgb8", is_bigendian=0, step=6,
                                         data=np.zeros(12, np.uint8))
        w.write(c, 1, ts.serialize_ros1(img, "sensor_msgs/msg/Image"))
    with pytest.raises(MissingIntrinsicsError, match="camera_info"):
        BagRecording(path)


def test_unaligned_bag_without_extrinsics_is_refused(tmp_path):
    kd = Intrinsics(32, 24, 30.0, 30.0, 15.5, 11.5)
    path = tmp_path / "noext.bag"
    write_realsense_bag(path, [(0.0, np.zeros((48, 64, 3), np.uint8), np.zeros((24, 32), np.uint16))], K, 0.001,
                        depth_k=kd, extrinsics=False)
    with pytest.raises(MissingIntrinsicsError, match="extrinsics"):
        BagRecording(path)
