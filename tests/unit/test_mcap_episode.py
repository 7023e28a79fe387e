"""EpisodeWriter: Foxglove-readable content, metadata, determinism and atomic output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from clutterbench.logs.mcap_episode import EpisodeWriter, read_episode

NAMES = ["mug", "box", "can"]
H, W = 4, 6


def _depth(t: float) -> np.ndarray:
    return (np.arange(H * W, dtype=np.float32).reshape(H, W) * 0.01 + 0.5 + t).astype(np.float32)


def _poses() -> np.ndarray:
    # [x, y, z, qw, qx, qy, qz]; distinct components so a swapped quaternion order shows up.
    return np.array(
        [
            [0.1, 0.2, 0.3, 0.9, 0.1, 0.2, 0.3],
            [1.0, 0.0, 0.05, 1.0, 0.0, 0.0, 0.0],
            [-0.4, 0.5, 0.6, 0.5, -0.5, 0.5, -0.5],
        ]
    )


def _write_episode(path: Path) -> Path:
    instance = np.zeros((H, W), dtype=np.uint8)
    instance[1:3, 2:4] = 2
    with EpisodeWriter(path, metadata={"seed": "7", "scene": "bin_clutter"}) as ep:
        ep.write_depth(0.0, _depth(0.0))
        ep.write_instance(0.0, instance)
        ep.write_poses(0.0, NAMES, _poses())
        ep.write_json(0.05, "/planner/decision", {"target": "mug", "score": 0.75, "ok": True})
        ep.write_depth(0.1, _depth(0.1))
        ep.set_outcome({"success": True, "collapsed": 0, "time_s": 1.25, "reason": "grasped"})
    return path


@pytest.fixture
def episode(tmp_path: Path) -> Path:
    return _write_episode(tmp_path / "ep.mcap")


def test_read_episode_summary(episode: Path) -> None:
    info = read_episode(episode)
    assert info["topics"] == {
        "/camera/depth": 2,
        "/camera/instance": 1,
        "/tf": 1,
        "/planner/decision": 1,
    }
    assert info["metadata"]["episode"] == {"scene": "bin_clutter", "seed": "7"}
    assert info["metadata"]["outcome"] == {
        "success": "True",
        "collapsed": "0",
        "time_s": "1.25",
        "reason": "grasped",
    }


def test_protobuf_messages_decode(episode: Path) -> None:
    with open(episode, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = list(
            reader.iter_decoded_messages(topics=["/camera/depth", "/camera/instance", "/tf"])
        )
    by_topic: dict[str, list] = {}
    for schema, channel, message, proto in decoded:
        assert schema is not None and schema.encoding == "protobuf"
        assert channel.message_encoding == "protobuf"
        assert message.log_time == message.publish_time
        by_topic.setdefault(channel.topic, []).append((schema, message, proto))

    depth = by_topic["/camera/depth"]
    assert [m.log_time for _, m, _ in depth] == [0, 100_000_000]
    schema, message, img = depth[1]
    assert schema.name == "foxglove.RawImage"
    assert (img.width, img.height, img.encoding, img.step) == (W, H, "32FC1", W * 4)
    assert img.frame_id == "camera"
    assert (img.timestamp.seconds, img.timestamp.nanos) == (0, 100_000_000)
    pixels = np.frombuffer(img.data, dtype="<f4").reshape(H, W)
    np.testing.assert_array_equal(pixels, _depth(0.1))

    ((_, _, inst),) = by_topic["/camera/instance"]
    assert (inst.width, inst.height, inst.encoding, inst.step) == (W, H, "mono8", W)
    assert np.frombuffer(inst.data, dtype=np.uint8).reshape(H, W)[1, 2] == 2

    ((schema, _, tf),) = by_topic["/tf"]
    assert schema.name == "foxglove.FrameTransforms"
    assert len(tf.transforms) == 3
    assert [t.child_frame_id for t in tf.transforms] == NAMES
    for t, row in zip(tf.transforms, _poses(), strict=True):
        assert t.parent_frame_id == "world"
        assert (t.translation.x, t.translation.y, t.translation.z) == tuple(row[:3])
        qw, qx, qy, qz = row[3:]
        assert (t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w) == (qx, qy, qz, qw)


def test_json_decision_decodes(episode: Path) -> None:
    with open(episode, "rb") as f:
        reader = make_reader(f)
        msgs = list(reader.iter_messages(topics=["/planner/decision"]))
    ((schema, channel, message),) = msgs
    assert channel.message_encoding == "json"
    assert schema is not None and schema.encoding == "jsonschema"
    assert json.loads(schema.data) == {"type": "object"}
    assert message.log_time == message.publish_time == 50_000_000
    assert json.loads(message.data) == {"target": "mug", "score": 0.75, "ok": True}


def test_same_episode_is_byte_identical(tmp_path: Path) -> None:
    a = _write_episode(tmp_path / "a.mcap")
    b = _write_episode(tmp_path / "b.mcap")
    assert a.read_bytes() == b.read_bytes()


def test_metadata_insertion_order_does_not_change_bytes(tmp_path: Path) -> None:
    paths = []
    for name, meta in (("x.mcap", {"a": "1", "b": "2"}), ("y.mcap", {"b": "2", "a": "1"})):
        with EpisodeWriter(tmp_path / name, metadata=meta) as ep:
            ep.write_json(0.0, "/planner/decision", {"k": 1})
        paths.append(tmp_path / name)
    assert paths[0].read_bytes() == paths[1].read_bytes()


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((H, W), dtype=np.float64),
        np.zeros((H, W), dtype=np.uint16),
        np.zeros((H, W, 1), dtype=np.float32),
    ],
)
def test_depth_must_be_float32_hxw(tmp_path: Path, bad: np.ndarray) -> None:
    with EpisodeWriter(tmp_path / "ep.mcap") as ep:
        with pytest.raises(ValueError, match="depth must be float32 metres, HxW"):
            ep.write_depth(0.0, bad)


def test_exception_leaves_no_file(tmp_path: Path) -> None:
    path = tmp_path / "ep.mcap"
    with pytest.raises(RuntimeError, match="sim exploded"):
        with EpisodeWriter(path) as ep:
            ep.write_depth(0.0, _depth(0.0))
            assert ep.tmp_path.exists()
            raise RuntimeError("sim exploded")
    assert not path.exists()
    assert not path.with_suffix(".mcap.tmp").exists()
    assert list(tmp_path.iterdir()) == []


def test_writes_outside_with_block_fail(tmp_path: Path) -> None:
    ep = EpisodeWriter(tmp_path / "ep.mcap")
    with pytest.raises(RuntimeError, match="inside a `with` block"):
        ep.write_json(0.0, "/planner/decision", {})
