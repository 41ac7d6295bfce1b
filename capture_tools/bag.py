"""RealSense Viewer ``.bag`` recordings (ROS1 bag) read with ``rosbags`` -- no ROS, no pyrealsense2.

Topics as librealsense writes them (``{s}`` sensor index, ``{i}`` stream index)::

    /device_0/sensor_{s}/Color_0/image/data          sensor_msgs/Image  (rgb8 | bgr8 | rgba8 | bgra8)
    /device_0/sensor_{s}/Color_0/info/camera_info    sensor_msgs/CameraInfo (K = fx 0 cx / 0 fy cy / 0 0 1)
    /device_0/sensor_{s}/Depth_0/image/data          sensor_msgs/Image  (16UC1 | mono16, depth units)
    /device_0/sensor_{s}/Depth_0/info/camera_info    sensor_msgs/CameraInfo
    /device_0/sensor_{s}/option/Depth Units/value    std_msgs/Float32   (metres per unit)
    /device_0/sensor_{s}/{Stream}_0/tf/0             geometry_msgs/Transform: the stream's extrinsics
                                                     (stream -> reference frame, quaternion x y z w)

Depth-to-colour = inv(colour -> reference) · (depth -> reference). Frames pair colour with the
nearest depth by header time (within ``max_dt``); timestamps are header stamps in seconds from
the first colour frame. Messages are read one at a time (:meth:`BagRecording.__iter__`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from rsart.camera import Intrinsics

from .readers import (CaptureError, MissingIntrinsicsError, RawFrame, Recording, StreamCalibration,
                      StreamMismatchError, TruncatedFileError)

COLOUR_TOPIC = "/device_0/sensor_1/Color_0/image/data"
DEPTH_TOPIC = "/device_0/sensor_0/Depth_0/image/data"


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC)


def _quat_matrix(q) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()


def _stamp(msg) -> float:
    s = msg.header.stamp
    return float(s.sec) + 1e-9 * float(s.nanosec)


def _intrinsics(info, where: str) -> Intrinsics:
    K = np.asarray(info.K, dtype=np.float64).reshape(-1)
    if K.size != 9 or K[0] <= 0 or K[4] <= 0 or info.width <= 0 or info.height <= 0:
        raise MissingIntrinsicsError(f"{where}: camera_info has no usable K / size")
    D = np.asarray(info.D, dtype=np.float64).reshape(-1)
    dist = tuple(float(x) for x in D) if D.size and np.any(D != 0) else None
    return Intrinsics(int(info.width), int(info.height), float(K[0]), float(K[4]), float(K[2]), float(K[5]), dist)


def _image(msg, where: str, depth: bool) -> np.ndarray:
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if data.size < h * step or h <= 0 or w <= 0:
        raise TruncatedFileError(f"{where}: image message holds {data.size} bytes, expected {h} x {step}")
    rows = data[: h * step].reshape(h, step)
    enc = msg.encoding.lower()
    if depth:
        if enc not in ("16uc1", "mono16"):
            raise CaptureError(f"{where}: depth encoding {msg.encoding!r} (expected 16UC1 or mono16)")
        dt = ">u2" if msg.is_bigendian else "<u2"
        return rows[:, : 2 * w].copy().view(dt).astype(np.uint16)
    ch = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}.get(enc)
    if ch is None:
        raise CaptureError(f"{where}: colour encoding {msg.encoding!r} (expected rgb8, bgr8, rgba8 or bgra8)")
    img = rows[:, : ch * w].reshape(h, w, ch)[..., :3]
    return np.ascontiguousarray(img[..., ::-1] if enc.startswith("bgr") else img)


class BagRecording(Recording):
    """A RealSense ``.bag``; calibration is read on open, images while iterating."""

    def __init__(self, path: str | Path, max_dt: float = 0.02) -> None:
        from rosbags.rosbag1 import Reader

        self.source = Path(path)
        self.max_dt = max_dt
        if not self.source.is_file():
            raise CaptureError(f"{self.source}: bag file not found")
        self._ts = _typestore()
        try:
            self._reader = Reader(self.source)
            self._reader.open()
        except Exception as e:  # rosbags raises its own ReaderError on truncated / foreign files
            raise TruncatedFileError(f"{self.source}: cannot read the bag ({type(e).__name__}: {e})") from None
        try:
            self._find_topics()
            self.calibration = self._read_calibration()
        finally:
            self._reader.close()

    def _find_topics(self) -> None:
        topics = {c.topic: c for c in self._reader.connections}
        colour = [t for t in topics if "/Color_" in t and t.endswith("/image/data")]
        depth = [t for t in topics if "/Depth_" in t and t.endswith("/image/data")]
        if not colour:
            raise CaptureError(f"{self.source}: no colour image topic (…/Color_0/image/data); topics: {sorted(topics)}")
        self.colour_topic = colour[0]
        self.depth_topic = depth[0] if depth else None
        self.counts = {t: c.msgcount for t, c in topics.items()}
        self.n_colour = sum(c.msgcount for c in self._reader.connections if c.topic == self.colour_topic)
        self.n_depth = sum(c.msgcount for c in self._reader.connections if c.topic == self.depth_topic)
        if self.depth_topic and self.n_depth == 0:
            raise StreamMismatchError(f"{self.source}: {self.n_colour} colour frames but no depth frames")

    def _first(self, topic_pred, where: str):
        conns = [c for c in self._reader.connections if topic_pred(c.topic)]
        if not conns:  # (rosbags reads *every* topic when given no connections)
            return None, None
        for conn, _, raw in self._reader.messages(connections=conns):
            try:
                return self._ts.deserialize_ros1(raw, conn.msgtype), conn.topic
            except Exception as e:
                raise TruncatedFileError(f"{self.source}: {conn.topic}: cannot decode ({e})") from None
        return None, None

    def _read_calibration(self) -> StreamCalibration:
        stream = lambda t: t.rsplit("/image/data", 1)[0]  # noqa: E731
        cinfo, _ = self._first(lambda t: t == stream(self.colour_topic) + "/info/camera_info", "colour info")
        if cinfo is None:
            raise MissingIntrinsicsError(f"{self.source}: no colour camera_info message "
                                         f"({stream(self.colour_topic)}/info/camera_info)")
        colour = _intrinsics(cinfo, f"{self.source}: colour camera_info")
        if self.depth_topic is None:
            return StreamCalibration(colour, 0.001)
        dinfo, _ = self._first(lambda t: t == stream(self.depth_topic) + "/info/camera_info", "depth info")
        if dinfo is None:
            raise MissingIntrinsicsError(f"{self.source}: no depth camera_info message "
                                         f"({stream(self.depth_topic)}/info/camera_info)")
        depth_k = _intrinsics(dinfo, f"{self.source}: depth camera_info")
        units, _ = self._first(lambda t: t.endswith("/option/Depth Units/value"), "depth units")
        if units is None:
            raise MissingIntrinsicsError(f"{self.source}: no depth scale (…/option/Depth Units/value)")
        scale = float(f"{float(units.data):.7g}")  # Float32 on the wire: 0.001 reads back as 0.0010000000475
        if not scale > 0:
            raise MissingIntrinsicsError(f"{self.source}: depth units {scale} is not positive")
        tf_d, _ = self._first(lambda t: t.startswith(stream(self.depth_topic) + "/tf/"), "depth tf")
        tf_c, _ = self._first(lambda t: t.startswith(stream(self.colour_topic) + "/tf/"), "colour tf")
        same = depth_k == colour or (depth_k.width, depth_k.height, depth_k.fx, depth_k.fy, depth_k.cx, depth_k.cy) == (
            colour.width, colour.height, colour.fx, colour.fy, colour.cx, colour.cy)
        if tf_d is None or tf_c is None:
            if same:
                return StreamCalibration(colour, scale)
            raise MissingIntrinsicsError(f"{self.source}: depth and colour are not aligned (different intrinsics) "
                                         f"and the depth/colour extrinsics (…/tf/0) are missing")

        def mat(tf) -> np.ndarray:
            T = np.eye(4)
            T[:3, :3] = _quat_matrix(tf.rotation)
            T[:3, 3] = [tf.translation.x, tf.translation.y, tf.translation.z]
            return T

        d2c = np.linalg.inv(mat(tf_c)) @ mat(tf_d)
        if same and np.allclose(d2c, np.eye(4), atol=1e-9):
            return StreamCalibration(colour, scale)
        return StreamCalibration(colour, scale, depth_k, d2c)

    def __len__(self) -> int:
        return self.n_colour

    def __iter__(self) -> Iterator[RawFrame]:
        from rosbags.rosbag1 import Reader

        cal = self.calibration
        topics = {self.colour_topic} | ({self.depth_topic} if self.depth_topic else set())
        pending: list[tuple[float, np.ndarray]] = []
        prev: tuple[float, np.ndarray] | None = None
        t0: float | None = None
        index = 0

        def emit(tc: float, rgb: np.ndarray, cands: list[tuple[float, np.ndarray]]) -> RawFrame | None:
            nonlocal index, t0
            depth = None
            if self.depth_topic:
                cands = [c for c in cands if c is not None]
                best = min(cands, key=lambda c: abs(c[0] - tc)) if cands else None
                if best is None or abs(best[0] - tc) > self.max_dt:
                    return None
                depth = cal.depth_in_colour(best[1])
            t0 = tc if t0 is None else t0
            f = RawFrame(index, f"{index:06d}", tc - t0, rgb, depth)
            index += 1
            return f

        try:
            reader = Reader(self.source)
            reader.open()
        except Exception as e:
            raise TruncatedFileError(f"{self.source}: cannot read the bag ({type(e).__name__}: {e})") from None
        try:
            conns = [c for c in reader.connections if c.topic in topics]
            it = reader.messages(connections=conns)
            while True:
                try:
                    conn, _, raw = next(it)
                except StopIteration:
                    break
                except Exception as e:
                    raise TruncatedFileError(f"{self.source}: bag ends early or is damaged after {index} frames "
                                             f"({type(e).__name__}: {e})") from None
                try:
                    msg = self._ts.deserialize_ros1(raw, conn.msgtype)
                except Exception as e:
                    raise TruncatedFileError(f"{self.source}: {conn.topic}: cannot decode a message ({e})") from None
                if conn.topic == self.colour_topic:
                    img = _image(msg, f"{self.source}: {conn.topic}", depth=False)
                    if (img.shape[1], img.shape[0]) != (cal.colour.width, cal.colour.height):
                        raise StreamMismatchError(f"{self.source}: colour frame is {img.shape[1]}x{img.shape[0]} "
                                                  f"but camera_info says {cal.colour.width}x{cal.colour.height}")
                    if self.depth_topic is None:
                        f = emit(_stamp(msg), img, [])
                        if f is not None:
                            yield f
                    else:
                        pending.append((_stamp(msg), img))
                else:
                    cur = (_stamp(msg), _image(msg, f"{self.source}: {conn.topic}", depth=True))
                    while pending and pending[0][0] <= cur[0]:
                        tc, img = pending.pop(0)
                        f = emit(tc, img, [prev, cur])
                        if f is not None:
                            yield f
                    prev = cur
            for tc, img in pending:
                f = emit(tc, img, [prev])
                if f is not None:
                    yield f
        finally:
            reader.close()
        if index == 0 and self.n_colour:
            raise StreamMismatchError(f"{self.source}: no colour frame has a depth frame within {self.max_dt * 1000:.0f} "
                                      f"ms ({self.n_colour} colour, {self.n_depth} depth messages)")


def write_realsense_bag(path: str | Path, frames: list[tuple[float, np.ndarray, np.ndarray]], colour: Intrinsics,
                        depth_scale: float, depth_k: Intrinsics | None = None,
                        depth_to_colour: np.ndarray | None = None, extrinsics: bool = True) -> None:
    """Write a small RealSense-style ROS1 bag: ``frames`` = (time s, (H, W, 3) uint8 RGB, (h, w) uint16 depth units).

    For tests and examples (a real bag comes from the RealSense Viewer). ``depth_to_colour`` (4, 4) is stored as the
    depth stream's tf with the colour stream as the reference (identity tf for colour); ``extrinsics=False`` leaves
    both tf topics out (as some recorders do).
    """
    from rosbags.rosbag1 import Writer
    from scipy.spatial.transform import Rotation

    ts = _typestore()
    T = ts.types
    depth_k = depth_k or colour
    d2c = np.eye(4) if depth_to_colour is None else np.asarray(depth_to_colour, float)

    def header(t: float, seq: int, frame: str):
        sec = int(t)
        return T["std_msgs/msg/Header"](seq=seq, stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t - sec) * 1e9))), frame_id=frame)

    def info(k: Intrinsics, t: float):
        Km = np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1], float)
        P = np.array([k.fx, 0, k.cx, 0, 0, k.fy, k.cy, 0, 0, 0, 1, 0], float)
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return T["sensor_msgs/msg/CameraInfo"](header=header(t, 0, ""), height=k.height, width=k.width,
                                              distortion_model="plumb_bob", D=np.zeros(5), K=Km,
                                              R=np.eye(3).ravel(), P=P, binning_x=0, binning_y=0, roi=roi)

    def tf(M: np.ndarray):
        q = Rotation.from_matrix(M[:3, :3]).as_quat()
        return T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=float(M[0, 3]), y=float(M[1, 3]), z=float(M[2, 3])),
            rotation=T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))

    path = Path(path)
    with Writer(path) as w:
        def conn(topic, typ):
            return w.add_connection(topic, typ, typestore=ts)

        t0 = frames[0][0] if frames else 0.0
        ns = lambda t: int(round(t * 1e9)) + 1  # noqa: E731  (bag times must be > 0)
        c_info = conn("/device_0/sensor_1/Color_0/info/camera_info", "sensor_msgs/msg/CameraInfo")
        d_info = conn("/device_0/sensor_0/Depth_0/info/camera_info", "sensor_msgs/msg/CameraInfo")
        units = conn("/device_0/sensor_0/option/Depth Units/value", "std_msgs/msg/Float32")
        if extrinsics:
            c_tf = conn("/device_0/sensor_1/Color_0/tf/0", "geometry_msgs/msg/Transform")
            d_tf = conn("/device_0/sensor_0/Depth_0/tf/0", "geometry_msgs/msg/Transform")
        c_img = conn(COLOUR_TOPIC, "sensor_msgs/msg/Image")
        d_img = conn(DEPTH_TOPIC, "sensor_msgs/msg/Image")
        ser = ts.serialize_ros1
        w.write(c_info, ns(t0), ser(info(colour, t0), "sensor_msgs/msg/CameraInfo"))
        w.write(d_info, ns(t0), ser(info(depth_k, t0), "sensor_msgs/msg/CameraInfo"))
        w.write(units, ns(t0), ser(T["std_msgs/msg/Float32"](data=float(depth_scale)), "std_msgs/msg/Float32"))
        if extrinsics:
            w.write(c_tf, ns(t0), ser(tf(np.eye(4)), "geometry_msgs/msg/Transform"))
            w.write(d_tf, ns(t0), ser(tf(d2c), "geometry_msgs/msg/Transform"))
        for seq, (t, rgb, dep) in enumerate(frames):
            h, wd = rgb.shape[:2]
            im = T["sensor_msgs/msg/Image"](header=header(t, seq, "color"), height=h, width=wd, encoding="rgb8",
                                           is_bigendian=0, step=3 * wd, data=np.ascontiguousarray(rgb).reshape(-1))
            w.write(c_img, ns(t), ser(im, "sensor_msgs/msg/Image"))
            if dep is not None:
                dh, dw = dep.shape
                dm = T["sensor_msgs/msg/Image"](header=header(t, seq, "depth"), height=dh, width=dw, encoding="16UC1",
                                               is_bigendian=0, step=2 * dw,
                                               data=np.ascontiguousarray(dep.astype("<u2")).view(np.uint8).reshape(-1))
                w.write(d_img, ns(t) + 1000, ser(dm, "sensor_msgs/msg/Image"))
