"""Deterministic MCAP episode logs that open in Foxglove Studio.

One episode = one `.mcap` file holding depth and instance images (foxglove.RawImage), object
poses (foxglove.FrameTransforms on /tf), planner decisions (JSON) and two metadata records:
"episode" (run parameters) and "outcome" (result). Trial episodes also carry the scene
(foxglove.SceneUpdate on /scene: the shelf boards and one cube per box, each in its own frame
so /tf moves it) and the camera (foxglove.CameraCalibration on /camera/calibration, its pose
as a FrameTransform world -> "camera" on /camera/tf), so Foxglove's 3D panel draws the scene
and projects the images into it (docs/foxglove.md). Every timestamp is simulation time, so
the same episode always gives a byte-identical file.
"""

from __future__ import annotations

import functools
import json
import os
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf.descriptor import FileDescriptor
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from google.protobuf.message import Message as ProtoMessage
from google.protobuf.timestamp_pb2 import Timestamp
from mcap.reader import make_reader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

from clutterbench.sim.geometry import matrix_to_quat

DEPTH_TOPIC = "/camera/depth"
INSTANCE_TOPIC = "/camera/instance"
TF_TOPIC = "/tf"
SCENE_TOPIC = "/scene"
CALIBRATION_TOPIC = "/camera/calibration"
CAMERA_TF_TOPIC = "/camera/tf"
"""The camera's pose: a topic of its own, so /tf holds the box poses only (Foxglove builds its
transform tree from every FrameTransforms topic)."""
WORLD_FRAME = "world"
CAMERA_FRAME = "camera"

SHELF_RGBA = (0.80, 0.66, 0.48, 0.35)
"""Plywood, translucent so that the boxes inside show through the side and top boards."""
BOX_PALETTE = (
    (0.122, 0.467, 0.706),
    (1.000, 0.498, 0.055),
    (0.173, 0.627, 0.173),
    (0.839, 0.153, 0.157),
    (0.580, 0.404, 0.741),
    (0.549, 0.337, 0.294),
    (0.890, 0.467, 0.761),
    (0.498, 0.498, 0.498),
    (0.737, 0.741, 0.133),
    (0.090, 0.745, 0.812),
)
"""Box k's colour is BOX_PALETTE[k % 10] (matplotlib's tab10), opaque."""

# zstd (mcap's default, read by Foxglove). zstandard.compress at its fixed default level is
# deterministic for a given zstd build; a zstd upgrade may change the bytes, not the content.
_COMPRESSION = CompressionType.ZSTD
# Pinned rather than left to the mcap default so that chunk boundaries (and so the bytes) do not
# move if the library changes its default.
_CHUNK_SIZE = 1024 * 1024
# The MCAP header holds only profile and library; neither is time-dependent. No standard profile
# covers protobuf + JSON channels, hence "".
_LIBRARY = f"clutterbench {LIBRARY_IDENTIFIER}"
_JSON_SCHEMA_NAME = "clutterbench.JsonObject"
_JSON_SCHEMA = json.dumps({"type": "object"}, sort_keys=True).encode()


@functools.cache
def _file_descriptor_set(message_class: type[ProtoMessage]) -> bytes:
    """The message's .proto file and all its transitive imports, as mcap_protobuf registers them.

    Dependencies come before the files that import them, each file once.
    """
    fds = FileDescriptorSet()
    seen: set[str] = set()

    def append(file_descriptor: FileDescriptor) -> None:
        for dep in file_descriptor.dependencies:
            if dep.name not in seen:
                seen.add(dep.name)
                append(dep)
        file_descriptor.CopyToProto(fds.file.add())

    append(message_class.DESCRIPTOR.file)
    return fds.SerializeToString(deterministic=True)


def _to_ns(t_s: float) -> int:
    """Simulation seconds -> integer nanoseconds (MCAP times are uint64)."""
    t_ns = int(round(t_s * 1e9))
    if t_ns < 0:
        raise ValueError(f"simulation time must be >= 0 s, got {t_s}")
    return t_ns


def _stamp(t_ns: int) -> Timestamp:
    return Timestamp(seconds=t_ns // 1_000_000_000, nanos=t_ns % 1_000_000_000)


def _str_map(name: str, data: dict[str, Any]) -> dict[str, str]:
    """Stringify values and sort keys: MCAP writes maps in insertion order."""
    for key in data:
        if not isinstance(key, str):
            raise TypeError(f"{name} metadata keys must be str, got {key!r}")
    return {key: str(data[key]) for key in sorted(data)}


def _add_cube(
    entity: Any,
    size: Sequence[float] | np.ndarray,
    rgba: Sequence[float],
    centre: Sequence[float] | np.ndarray | None = None,
) -> None:
    cube = entity.cubes.add()
    if centre is not None:
        cx, cy, cz = np.asarray(centre, dtype=np.float64).tolist()
        cube.pose.position.x, cube.pose.position.y, cube.pose.position.z = cx, cy, cz
    cube.pose.orientation.w = 1.0
    sx, sy, sz = np.asarray(size, dtype=np.float64).tolist()
    cube.size.x, cube.size.y, cube.size.z = sx, sy, sz
    cube.color.r, cube.color.g, cube.color.b, cube.color.a = (float(c) for c in rgba)


class EpisodeWriter:
    """Context manager writing one episode to `path` via `<path>.tmp` and an atomic rename.

    On an exception inside the block the temp file is removed and nothing appears at `path`.
    """

    def __init__(self, path: Path, metadata: dict[str, str] | None = None) -> None:
        self.path = Path(path)
        self.tmp_path = self.path.with_suffix(self.path.suffix + ".tmp")
        self._metadata = _str_map("episode", dict(metadata or {}))
        self._outcome: dict[str, str] | None = None
        self._stream: IO[bytes] | None = None
        self._writer: Writer | None = None
        self._used = False
        self._schemas: dict[str, int] = {}
        # topic -> (channel id, message encoding)
        self._channels: dict[str, tuple[int, str]] = {}

    def __enter__(self) -> EpisodeWriter:
        if self._used:
            raise RuntimeError("an EpisodeWriter writes one episode; make a new one")
        self._used = True
        self.path.parent.mkdir(parents=True, exist_ok=True)
        stream = open(self.tmp_path, "wb")  # closed in __exit__
        try:
            writer = Writer(stream, chunk_size=_CHUNK_SIZE, compression=_COMPRESSION)
            writer.start(profile="", library=_LIBRARY)
        except BaseException:
            stream.close()
            self.tmp_path.unlink(missing_ok=True)
            raise
        self._stream, self._writer = stream, writer
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        stream, writer = self._require()
        self._stream = None
        self._writer = None
        done = False
        try:
            if exc_type is None:
                writer.add_metadata("episode", self._metadata)
                if self._outcome is not None:
                    writer.add_metadata("outcome", self._outcome)
                writer.finish()
                stream.flush()
                os.fsync(stream.fileno())
                stream.close()
                os.replace(self.tmp_path, self.path)
                done = True
        finally:
            if not done:
                stream.close()
                self.tmp_path.unlink(missing_ok=True)

    def _require(self) -> tuple[IO[bytes], Writer]:
        if self._stream is None or self._writer is None:
            raise RuntimeError("EpisodeWriter must be used inside a `with` block")
        return self._stream, self._writer

    def _channel(self, topic: str, encoding: str, schema_name: str, schema_data: bytes) -> int:
        _, writer = self._require()
        if topic in self._channels:
            channel_id, existing = self._channels[topic]
            if existing != encoding:
                raise ValueError(f"topic {topic} already carries {existing} messages")
            return channel_id
        schema_id = self._schemas.get(schema_name)
        if schema_id is None:
            schema_encoding = (
                SchemaEncoding.Protobuf
                if encoding == MessageEncoding.Protobuf
                else SchemaEncoding.JSONSchema
            )
            schema_id = writer.register_schema(schema_name, schema_encoding, schema_data)
            self._schemas[schema_name] = schema_id
        channel_id = writer.register_channel(topic, encoding, schema_id, metadata={})
        self._channels[topic] = (channel_id, encoding)
        return channel_id

    def write_proto(self, topic: str, t_s: float, message: ProtoMessage) -> None:
        """Any protobuf message (e.g. a foxglove_schemas_protobuf one) on `topic` at `t_s`;
        the channel's schema is the message's .proto file set, registered on first use."""
        descriptor = message.DESCRIPTOR
        channel_id = self._channel(
            topic,
            MessageEncoding.Protobuf,
            descriptor.full_name,
            _file_descriptor_set(type(message)),
        )
        t_ns = _to_ns(t_s)
        _, writer = self._require()
        writer.add_message(
            channel_id,
            log_time=t_ns,
            data=message.SerializeToString(deterministic=True),
            publish_time=t_ns,
        )

    def write_depth(self, t_s: float, depth_m: np.ndarray, frame_id: str = "camera") -> None:
        """Depth image in metres (0 or inf where nothing was hit, as rendered)."""
        if not isinstance(depth_m, np.ndarray) or depth_m.ndim != 2 or depth_m.dtype != np.float32:
            raise ValueError("depth must be float32 metres, HxW")
        height, width = depth_m.shape
        image = RawImage(
            timestamp=_stamp(_to_ns(t_s)),
            frame_id=frame_id,
            width=width,
            height=height,
            encoding="32FC1",
            step=width * 4,
            # 32FC1 in Foxglove is little-endian, rows packed with no padding.
            data=np.ascontiguousarray(depth_m, dtype="<f4").tobytes(),
        )
        self.write_proto(DEPTH_TOPIC, t_s, image)

    def write_instance(self, t_s: float, instance: np.ndarray, frame_id: str = "camera") -> None:
        """Per-pixel instance ids (0 = background), same camera as the depth image."""
        if not isinstance(instance, np.ndarray) or instance.ndim != 2 or instance.dtype != np.uint8:
            raise ValueError("instance must be uint8 ids, HxW")
        self.write_mono8(t_s, INSTANCE_TOPIC, instance, frame_id)

    def write_mono8(
        self, t_s: float, topic: str, image: np.ndarray, frame_id: str = "camera"
    ) -> None:
        """A uint8 HxW image (masks, heatmaps scaled to 0-255) on `topic`."""
        if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype != np.uint8:
            raise ValueError(f"{topic}: image must be uint8, HxW")
        height, width = image.shape
        message = RawImage(
            timestamp=_stamp(_to_ns(t_s)),
            frame_id=frame_id,
            width=width,
            height=height,
            encoding="mono8",
            step=width,
            data=np.ascontiguousarray(image).tobytes(),
        )
        self.write_proto(topic, t_s, message)

    def write_poses(self, t_s: float, names: list[str], poses: np.ndarray) -> None:
        """Object poses as rows [x, y, z, qw, qx, qy, qz]: SAPIEN order, world frame, metres."""
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim != 2 or poses.shape[1] != 7 or poses.shape[0] != len(names):
            raise ValueError(f"poses must be (len(names), 7), got {poses.shape} for {len(names)}")
        stamp = _stamp(_to_ns(t_s))
        message = FrameTransforms()
        for name, (x, y, z, qw, qx, qy, qz) in zip(names, poses.tolist(), strict=True):
            transform: FrameTransform = message.transforms.add()
            transform.timestamp.CopyFrom(stamp)
            transform.parent_frame_id = WORLD_FRAME
            transform.child_frame_id = name
            transform.translation.x, transform.translation.y, transform.translation.z = x, y, z
            # foxglove.Quaternion is (x, y, z, w); SAPIEN puts w first.
            transform.rotation.x = qx
            transform.rotation.y = qy
            transform.rotation.z = qz
            transform.rotation.w = qw
        self.write_proto(TF_TOPIC, t_s, message)

    def write_scene(
        self,
        t_s: float,
        sizes_m: np.ndarray,
        boards: Sequence[tuple[str, np.ndarray, np.ndarray]],
        names: Sequence[str] | None = None,
    ) -> None:
        """Replace the scene on /scene: delete every entity shown so far (an earlier episode's
        boxes), then the shelf `boards` [(name, half extents, centre)] as static cubes in the
        world frame (ids "shelf/<name>") and box k as a cube of full extents `sizes_m[k]`
        (its local x, y, z, as SAPIEN builds it) centred in frame `names[k]` (default
        "box_<k>", the /tf child frames of `write_poses`), frame-locked so that the box
        poses move it; ids are the frame names, colours BOX_PALETTE."""
        sizes = np.asarray(sizes_m, dtype=np.float64)
        if sizes.ndim != 2 or sizes.shape[1] != 3:
            raise ValueError(f"sizes_m must be (N, 3), got {sizes.shape}")
        if not (np.all(np.isfinite(sizes)) and np.all(sizes > 0)):
            raise ValueError("box sizes must be finite and positive")
        names = [f"box_{k}" for k in range(len(sizes))] if names is None else list(names)
        if len(names) != len(sizes):
            raise ValueError(f"{len(names)} names for {len(sizes)} boxes")
        stamp = _stamp(_to_ns(t_s))
        update = SceneUpdate()
        deletion = update.deletions.add()
        deletion.timestamp.CopyFrom(stamp)
        deletion.type = SceneEntityDeletion.Type.ALL
        for name, half, centre in boards:
            entity = update.entities.add()
            entity.timestamp.CopyFrom(stamp)
            entity.frame_id = WORLD_FRAME
            entity.id = f"shelf/{name}"
            entity.frame_locked = True
            _add_cube(entity, 2.0 * np.asarray(half, dtype=np.float64), SHELF_RGBA, centre)
        for k, (name, size) in enumerate(zip(names, sizes.tolist(), strict=True)):
            entity = update.entities.add()
            entity.timestamp.CopyFrom(stamp)
            entity.frame_id = name
            entity.id = name
            entity.frame_locked = True
            _add_cube(entity, size, (*BOX_PALETTE[k % len(BOX_PALETTE)], 1.0))
        self.write_proto(SCENE_TOPIC, t_s, update)

    def delete_scene_entities(self, t_s: float, ids: Sequence[str]) -> None:
        """Take entities off /scene from `t_s` on (e.g. "box_3" once it left the shelf)."""
        stamp = _stamp(_to_ns(t_s))
        update = SceneUpdate()
        for entity_id in ids:
            deletion = update.deletions.add()
            deletion.timestamp.CopyFrom(stamp)
            deletion.type = SceneEntityDeletion.Type.MATCHING_ID
            deletion.id = entity_id
        self.write_proto(SCENE_TOPIC, t_s, update)

    def write_camera(
        self,
        t_s: float,
        K: np.ndarray,
        T_world_from_cam: np.ndarray,
        width: int,
        height: int,
        frame_id: str = CAMERA_FRAME,
    ) -> None:
        """The pinhole camera of the images: its pose (the OpenCV optical frame, x right,
        y down, z forward, in the world frame) as a FrameTransform world -> `frame_id` on
        /camera/tf, and its intrinsics `K` (3x3, pixels) as a foxglove.CameraCalibration on
        /camera/calibration (no distortion: plumb_bob with D = 0, P = [K | 0])."""
        K = np.asarray(K, dtype=np.float64)
        T = np.asarray(T_world_from_cam, dtype=np.float64)
        if K.shape != (3, 3) or T.shape != (4, 4):
            raise ValueError(f"K must be 3x3 and T_world_from_cam 4x4, got {K.shape}, {T.shape}")
        stamp = _stamp(_to_ns(t_s))
        tf = FrameTransforms()
        transform: FrameTransform = tf.transforms.add()
        transform.timestamp.CopyFrom(stamp)
        transform.parent_frame_id = WORLD_FRAME
        transform.child_frame_id = frame_id
        x, y, z = T[:3, 3].tolist()
        transform.translation.x, transform.translation.y, transform.translation.z = x, y, z
        qw, qx, qy, qz = (float(v) for v in matrix_to_quat(T[:3, :3]))
        transform.rotation.x = qx
        transform.rotation.y = qy
        transform.rotation.z = qz
        transform.rotation.w = qw
        self.write_proto(CAMERA_TF_TOPIC, t_s, tf)
        P = np.zeros((3, 4))
        P[:, :3] = K
        calibration = CameraCalibration(
            timestamp=stamp,
            frame_id=frame_id,
            width=int(width),
            height=int(height),
            distortion_model="plumb_bob",
            D=[0.0] * 5,
            K=K.ravel().tolist(),
            R=np.eye(3).ravel().tolist(),
            P=P.ravel().tolist(),
        )
        self.write_proto(CALIBRATION_TOPIC, t_s, calibration)

    def write_json(self, t_s: float, topic: str, payload: dict[str, Any]) -> None:
        """A JSON object (e.g. a planner decision on /planner/decision)."""
        channel_id = self._channel(topic, MessageEncoding.JSON, _JSON_SCHEMA_NAME, _JSON_SCHEMA)
        t_ns = _to_ns(t_s)
        _, writer = self._require()
        writer.add_message(
            channel_id,
            log_time=t_ns,
            data=json.dumps(payload, sort_keys=True).encode(),
            publish_time=t_ns,
        )

    def set_outcome(self, outcome: dict[str, str | bool | float | int]) -> None:
        """Episode result, written as the "outcome" metadata record at close (values as str)."""
        self._outcome = _str_map("outcome", outcome)


def read_episode(path: Path) -> dict[str, dict[str, Any]]:
    """Summarise an episode: {"topics": {topic: message count}, "metadata": {name: dict}}."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        topics: dict[str, int] = {}
        summary = reader.get_summary()
        if summary is not None and summary.statistics is not None:
            counts = summary.statistics.channel_message_counts
            for channel_id, channel in sorted(summary.channels.items()):
                topics[channel.topic] = topics.get(channel.topic, 0) + counts.get(channel_id, 0)
        else:
            for _, channel, _ in reader.iter_messages(log_time_order=False):
                topics[channel.topic] = topics.get(channel.topic, 0) + 1
        metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
    return {"topics": topics, "metadata": metadata}
