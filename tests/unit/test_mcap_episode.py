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


# -- the scene and the camera (trial episodes) ----------------------------------------------
SIZES = np.array([[0.05, 0.10, 0.02], [0.08, 0.06, 0.04]])
BOARDS = [
    ("floor", np.array([0.14, 0.183, 0.009]), np.array([0.14, 0.0, -0.009])),
    ("back", np.array([0.009, 0.183, 0.174]), np.array([0.289, 0.0, 0.165])),
]
K = np.array([[300.0, 0.0, 32.0], [0.0, 310.0, 24.0], [0.0, 0.0, 1.0]])


def _camera_pose() -> np.ndarray:
    """An OpenCV camera in front of the shelf looking into it (+x), tilted down 20 degrees."""
    a = np.deg2rad(20.0)
    forward = np.array([np.cos(a), 0.0, -np.sin(a)])  # z: along the optical axis
    right = np.array([0.0, -1.0, 0.0])  # x: to the camera's right (world -y)
    down = np.cross(forward, right)  # y = z x x
    T = np.eye(4)
    T[:3, :3] = np.stack([right, down, forward], axis=1)
    T[:3, 3] = [-0.45, 0.02, 0.30]
    return T


def _decoded(path: Path, topic: str) -> list:
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [
            (schema.name, message.log_time, proto)
            for schema, _, message, proto in reader.iter_decoded_messages(topics=[topic])
        ]


def _quat_matrix(q) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_scene_update_has_shelf_and_box_cubes(tmp_path: Path) -> None:
    path = tmp_path / "ep.mcap"
    with EpisodeWriter(path) as ep:
        ep.write_scene(0.0, SIZES, BOARDS)
        ep.delete_scene_entities(0.5, ["box_1"])
    (name, t0, first), (_, t1, second) = _decoded(path, "/scene")
    assert name == "foxglove.SceneUpdate" and (t0, t1) == (0, 500_000_000)
    # an episode's scene replaces whatever was shown before
    assert [(d.type, d.id) for d in first.deletions] == [(1, "")]  # ALL
    ids = [e.id for e in first.entities]
    assert ids == ["shelf/floor", "shelf/back", "box_0", "box_1"]
    for entity, (_, half, centre) in zip(first.entities[:2], BOARDS, strict=True):
        assert entity.frame_id == "world"
        ((cube,),) = [entity.cubes]
        p = cube.pose.position
        assert (p.x, p.y, p.z) == tuple(centre)
        assert (cube.size.x, cube.size.y, cube.size.z) == tuple(2 * half)
    colours = set()
    for entity, size in zip(first.entities[2:], SIZES, strict=True):
        assert entity.frame_id == entity.id and entity.frame_locked  # moved by /tf
        ((cube,),) = [entity.cubes]
        assert (cube.size.x, cube.size.y, cube.size.z) == tuple(size)
        p, q = cube.pose.position, cube.pose.orientation
        assert (p.x, p.y, p.z, q.x, q.y, q.z, q.w) == (0, 0, 0, 0, 0, 0, 1)
        assert cube.color.a == 1.0
        colours.add((cube.color.r, cube.color.g, cube.color.b))
    assert len(colours) == 2
    assert not second.entities
    assert [(d.type, d.id) for d in second.deletions] == [(0, "box_1")]  # MATCHING_ID


def test_camera_calibration_and_optical_frame(tmp_path: Path) -> None:
    path = tmp_path / "ep.mcap"
    T = _camera_pose()
    with EpisodeWriter(path) as ep:
        ep.write_camera(0.25, K, T, width=64, height=48)
    ((name, t, cal),) = _decoded(path, "/camera/calibration")
    assert name == "foxglove.CameraCalibration" and t == 250_000_000
    assert (cal.timestamp.seconds, cal.timestamp.nanos) == (0, 250_000_000)
    assert (cal.frame_id, cal.width, cal.height) == ("camera", 64, 48)
    assert cal.distortion_model == "plumb_bob" and list(cal.D) == [0.0] * 5
    np.testing.assert_array_equal(np.reshape(cal.K, (3, 3)), K)
    np.testing.assert_array_equal(np.reshape(cal.P, (3, 4)), np.hstack([K, np.zeros((3, 1))]))
    np.testing.assert_array_equal(np.reshape(cal.R, (3, 3)), np.eye(3))
    ((name, _, tf),) = _decoded(path, "/camera/tf")
    assert name == "foxglove.FrameTransforms"
    ((tr,),) = [tf.transforms]
    assert (tr.parent_frame_id, tr.child_frame_id) == ("world", "camera")
    assert (tr.translation.x, tr.translation.y, tr.translation.z) == tuple(T[:3, 3])
    np.testing.assert_allclose(_quat_matrix(tr.rotation), T[:3, :3], atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 90.0, 179.0, 180.0, -120.0])
@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 2, 3)])
def test_camera_rotation_round_trips(tmp_path: Path, angle: float, axis) -> None:
    """Every branch of the matrix -> quaternion conversion (trace > 0 and each diagonal)."""
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.deg2rad(angle)
    skew = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(a) * skew + (1 - np.cos(a)) * skew @ skew
    with EpisodeWriter(tmp_path / "ep.mcap") as ep:
        ep.write_camera(0.0, K, T, 64, 48)
    ((_, _, tf),) = _decoded(tmp_path / "ep.mcap", "/camera/tf")
    np.testing.assert_allclose(_quat_matrix(tf.transforms[0].rotation), T[:3, :3], atol=1e-12)


def _tiny_trial_episode():
    from clutterbench.observation import CameraModel
    from clutterbench.trials.core.harness import EpisodeLog, EpisodeResult

    log = EpisodeLog()
    log.scene(0.0, SIZES, BOARDS, CameraModel(K=K, T_world_from_cam=_camera_pose()), (H, W))
    poses = np.array([[0.1, 0.0, 0.01, 1.0, 0, 0, 0], [0.1, 0.0, 0.04, 1.0, 0, 0, 0]])
    log.observation(0.0, _depth(0.0), np.zeros((H, W), dtype=np.uint8))
    log.poses(0.0, poses, frozenset())
    log.json(0.0, "/planner/decision", {"pull": 1, "hold": None})
    poses = poses.copy()
    poses[1, 2] = -50.0  # taken out: parked below the floor
    log.observation(0.5, _depth(0.5), np.zeros((H, W), dtype=np.uint8))
    log.poses(0.5, poses, frozenset({1}))
    log.poses(0.75, poses, frozenset({1}))
    return EpisodeResult({"episode": 0, "success": True, "steps": []}, log)


def test_trial_mcap_shows_the_scene_and_camera(tmp_path: Path) -> None:
    """write_mcap (every trial's MCAP): the scene at each episode's start, cubes of the
    boxes' sizes, the camera beside every depth image, removed boxes taken off /scene."""
    from clutterbench.trials.core.harness import EPISODE_GAP_S, write_mcap

    path = tmp_path / "episodes.mcap"
    write_mcap(path, [_tiny_trial_episode(), _tiny_trial_episode()], {"condition": "c"})
    topics = read_episode(path)["topics"]
    assert topics["/scene"] == 4 and topics["/camera/calibration"] == 4
    assert topics["/camera/tf"] == 4 and topics["/tf"] == 6  # the camera is not on /tf
    second = int((0.75 + EPISODE_GAP_S) * 1e9)
    scene = _decoded(path, "/scene")
    assert [t for _, t, _ in scene] == [0, 500_000_000, second, second + 500_000_000]
    for _, _, start in scene[::2]:
        boxes = [e for e in start.entities if e.id.startswith("box_")]
        assert [e.frame_id for e in boxes] == ["box_0", "box_1"]
        sizes = [(e.cubes[0].size.x, e.cubes[0].size.y, e.cubes[0].size.z) for e in boxes]
        assert sizes == [tuple(s) for s in SIZES]
        assert [e.id for e in start.entities if e.frame_id == "world"] == [
            "shelf/floor",
            "shelf/back",
        ]
    for _, _, removal in scene[1::2]:
        assert [d.id for d in removal.deletions] == ["box_1"]  # once, when it left
    cals = _decoded(path, "/camera/calibration")
    depth_times = [t for _, t, _ in _decoded(path, "/camera/depth")]
    assert [t for _, t, _ in cals] == depth_times
    for _, _, cal in cals:
        assert cal.frame_id == "camera" and (cal.width, cal.height) == (W, H)
        np.testing.assert_array_equal(np.reshape(cal.K, (3, 3)), K)
    first = _tiny_trial_episode()
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    write_mcap(a, [first], {})
    write_mcap(b, [_tiny_trial_episode()], {})
    assert a.read_bytes() == b.read_bytes()


def test_camera_frame_projects_as_the_camera_model(tmp_path: Path) -> None:
    """A world point through the MCAP's camera transform and K lands on the pixel
    CameraModel.world_to_pixel gives: the frame is OpenCV's, as Foxglove expects."""
    from clutterbench.observation import CameraModel
    from clutterbench.trials.core.harness import write_mcap

    write_mcap(tmp_path / "e.mcap", [_tiny_trial_episode()], {})
    _, _, tf = _decoded(tmp_path / "e.mcap", "/camera/tf")[0]
    _, _, cal = _decoded(tmp_path / "e.mcap", "/camera/calibration")[0]
    tr = tf.transforms[0]
    R = _quat_matrix(tr.rotation)
    t = np.array([tr.translation.x, tr.translation.y, tr.translation.z])
    point = np.array([0.12, 0.03, 0.05])
    p_cam = R.T @ (point - t)
    uv = (np.reshape(cal.P, (3, 4)) @ np.append(p_cam, 1.0))[:2] / p_cam[2]
    u, v, z = CameraModel(K=K, T_world_from_cam=_camera_pose()).world_to_pixel(point)
    assert z > 0
    np.testing.assert_allclose(uv, [u, v], atol=1e-9)


def test_the_saved_foxglove_layout_names_topics_the_trials_write(tmp_path: Path) -> None:
    from clutterbench.trials.core.harness import write_mcap

    layout = json.loads(
        (Path(__file__).resolve().parents[2] / "docs/foxglove-layout.json").read_text()
    )
    named: set[str] = set()

    def walk(node) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                if key.startswith("/"):
                    named.add(key)
                walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)
        elif isinstance(node, str) and node.startswith("/"):
            named.add(node)

    walk(layout["configById"])
    write_mcap(tmp_path / "e.mcap", [_tiny_trial_episode()], {})
    written = set(read_episode(tmp_path / "e.mcap")["topics"])
    assert {"/scene", "/camera/depth", "/camera/calibration", "/planner/decision"} <= named
    assert named <= written
