"""The test set's sensed tracks (stage testset): the ideal track (data/testset, the renderer's
exact depth) again with every depth image passed through a depth-sensor model (sim/sensor.py,
docs/sensing.md), written beside it as <ideal>_sensed/<preset> (data/testset_sensed/d415):
scenes.npz with
the sensed `depth_m` and every other array the ideal track's own, its own manifest (its
`sensing` preset and its own sha256) and the same numpy-only loader.

Each image is sensed as the pipeline's observe() senses a picture: `sense(depth_m,
camera, preset(name), observation_rng(0, depth_m))`, seeded by the image itself, so the
track's bytes are the same on every run."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.data.testset_load import load
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, save_npz, write_json
from clutterbench.sim.config import CameraConfig

IDEAL = "ideal"
"""The track of the renderer's exact depth (data/testset itself)."""
SEED = 0
"""observation_rng's seed, as sim/render.py observe() seeds every sensed picture."""


def track_dir(ideal_dir: Path, track: str) -> Path:
    """Where a track lies: the ideal track's folder itself, a sensed one in the sensed tracks'
    folder beside it (data/testset -> data/testset_sensed/d415)."""
    return ideal_dir if track == IDEAL else sensed_root(ideal_dir) / track


def sensed_root(ideal_dir: Path) -> Path:
    """The folder of the sensed tracks beside the ideal one (data/testset_sensed); it exists,
    perhaps empty but for its index, whenever the stage ran (a fixed dvc out)."""
    return ideal_dir.with_name(f"{ideal_dir.name}_sensed")


def sensed_tracks(ideal_dir: Path) -> dict[str, str]:
    """preset -> the manifest sha256 of each sensed track written beside ideal_dir."""
    out = {}
    for path in sorted(sensed_root(ideal_dir).glob("*/manifest.json")):
        manifest = read_json(path)
        track = manifest.get("sensing")
        if track and path.parent == track_dir(ideal_dir, track):
            out[str(track)] = str(manifest["sha256"])
    return out


def sensed_depth(depth_m: np.ndarray, camera: CameraConfig, name: str) -> np.ndarray:
    """(S, H, W) float32: each image through preset `name`'s sensor model, seeded by itself
    (observation_rng(0, image)), the camera's focal length focal_px(image_size, fovy_deg)."""
    from clutterbench.sim.sensor import focal_px, observation_rng, pinhole, preset, sense

    cfg = preset(name)
    if cfg is None:
        raise ClutterbenchError(f"sensed track {name!r}: a sensor preset, not the ideal depth")
    model = pinhole(focal_px(camera.image_size, camera.fovy_deg), depth_m.shape[1:])
    images = [np.ascontiguousarray(d, dtype=np.float32) for d in depth_m]
    return np.stack([sense(d, model, cfg, observation_rng(SEED, d)) for d in images])


def export_sensed(ideal_dir: Path, name: str, camera: CameraConfig) -> dict[str, Any]:
    """Write the sensed track of preset `name` beside the ideal track in ideal_dir
    (track_dir): its scenes.npz (depth_m sensed, every other array unchanged), manifest.json
    (the ideal one's with `sensing`, `sensed_from` and its own sha256; no pins) and
    load_testset.py. Returns the manifest."""
    ts = load(ideal_dir)
    ideal = ts.pop("manifest")
    if ideal.get("sensing"):
        raise ClutterbenchError(f"{ideal_dir}: already a sensed track ({ideal['sensing']})")
    ts["depth_m"] = sensed_depth(ts["depth_m"], camera, name)
    out = track_dir(ideal_dir, name)
    out.mkdir(parents=True, exist_ok=True)
    save_npz(out / "scenes.npz", ts)  # byte-identical for identical arrays
    manifest = {k: v for k, v in ideal.items() if k != "files"}  # pins: publish-testset's
    manifest["arrays"] = dict(ideal["arrays"]) if "arrays" in ideal else {}
    manifest["arrays"]["depth_m"] = (
        f"(S, H, W) float32: the ideal track's depth through the {name} sensor model "
        "(docs/sensing.md), metres along the optical axis; 0 where it returned nothing"
    )
    manifest |= {
        "sensing": name,
        "sensed_from": {
            "sha256": ideal["sha256"],
            "model": f"sim/sensor.py sense(depth_m, camera, preset({name!r}), "
            f"observation_rng({SEED}, depth_m)) per image, f = focal_px(image_size, fovy_deg)",
        },
        "sha256": hashlib.sha256((out / "scenes.npz").read_bytes()).hexdigest(),
    }
    write_json(out / "manifest.json", manifest)
    shutil.copyfile(Path(__file__).with_name("testset_load.py"), out / "load_testset.py")
    return manifest
