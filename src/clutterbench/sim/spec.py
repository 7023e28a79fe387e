"""JSON scene specs: every box's size and pose, the shelf and the camera.

Any scene can be saved and loaded alone, to regenerate, inspect or replay it. Poses are the
settled poses, so a loaded spec is already at rest. A loaded spec is validated in two
passes, each stopping with one line naming the key or the box: `check_spec_dict` checks the
JSON's keys, types and shapes (the format: docs/spec-format.md), `validate_spec` what a
world cannot hold (a box that is not finite, has no size, a non-unit rotation, a centre
outside the shelf, or overlaps another box).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.config import parse
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text
from clutterbench.sim.config import FAMILY_NAMES, CameraConfig
from clutterbench.sim.geometry import box_aabb_half_extents, obb_penetration_m
from clutterbench.sim.shelf import Shelf

SPEC_VERSION = 1
MAX_PENETRATION_M = 0.001
"""Two boxes overlapping deeper than this cannot both be where the spec puts them."""
QUAT_NORM_TOL = 1e-3
"""A quaternion within this of unit length is normalized; further off, the spec is refused."""
_QUAT_EXACT_TOL = 1e-6  # float32 round-off: left untouched so replays stay bit-identical
SPEC_KEYS = ("version", "family", "shelf", "camera", "boxes", "meta")
"""Keys of a spec's JSON object (docs/spec-format.md) ..."""
REQUIRED_KEYS = ("version", "shelf", "camera", "boxes")
"""... of which `family` and `meta` may be left out."""
BOX_KEYS = ("size_m", "pose", "type", "density_kg_m3")
"""Keys of one box; `type` and `density_kg_m3` may be left out."""
SPEC_FAMILIES = (*FAMILY_NAMES, "stack", "custom")
"""A spec's `family`: a scene family of sim/families, `stack` (`clutterbench scene make
--stack`) or `custom` (made by hand; the default)."""


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    sizes_m: np.ndarray
    """(N, 3) box extents along the box's local x, y, z (metres)."""
    poses: np.ndarray
    """(N, 7) box poses [x, y, z, qw, qx, qy, qz] in the shelf frame (metres)."""
    shelf: Shelf = Shelf()
    camera: CameraConfig = CameraConfig()
    family: str = "custom"
    """Scene family that generated it."""
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)
    """Free-form provenance: dataset, scene index, seed."""
    type_ids: np.ndarray | None = None
    """(N,) int catalogue type of each box (-1: none), or None for all."""
    densities_kg_m3: np.ndarray | None = None
    """(N,) density of each box (NaN: sim.physics.density_kg_m3), or None for all."""

    @property
    def n(self) -> int:
        return int(self.sizes_m.shape[0])

    def density(self, k: int, default: float) -> float:
        """Box k's density: its own if the spec gives one, else `default`."""
        if self.densities_kg_m3 is None or np.isnan(self.densities_kg_m3[k]):
            return default
        return float(self.densities_kg_m3[k])

    def _box_dict(self, k: int) -> dict[str, Any]:
        box: dict[str, Any] = {
            "size_m": [float(v) for v in self.sizes_m[k]],
            "pose": [float(v) for v in self.poses[k]],
        }
        if self.type_ids is not None and self.type_ids[k] >= 0:
            box["type"] = int(self.type_ids[k])
        if self.densities_kg_m3 is not None and not np.isnan(self.densities_kg_m3[k]):
            box["density_kg_m3"] = float(self.densities_kg_m3[k])
        return box

    def to_dict(self) -> dict[str, Any]:
        return {
            "version": SPEC_VERSION,
            "family": self.family,
            "shelf": dataclasses.asdict(self.shelf),
            "camera": dataclasses.asdict(self.camera),
            "boxes": [self._box_dict(k) for k in range(self.n)],
            "meta": self.meta,
        }

    def to_json(self) -> str:
        # repr-exact floats: a reloaded spec reproduces the poses bit for bit.
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, d: Any, where: str = "spec") -> SceneSpec:
        shelf, camera = check_spec_dict(d, where)
        boxes = d["boxes"]
        sizes = np.array([b["size_m"] for b in boxes], dtype=np.float64).reshape(-1, 3)
        poses = np.array([b["pose"] for b in boxes], dtype=np.float64).reshape(-1, 7)
        types = np.array([b.get("type", -1) for b in boxes], dtype=np.int64)
        dens = np.array([float(b.get("density_kg_m3", np.nan)) for b in boxes])
        spec = cls(
            sizes_m=sizes,
            poses=poses,
            shelf=shelf,
            camera=camera,
            family=d.get("family", "custom"),
            meta=d.get("meta", {}),
            type_ids=types if np.any(types >= 0) else None,
            densities_kg_m3=dens if not np.all(np.isnan(dens)) else None,
        )
        return validate_spec(spec, where)

    @classmethod
    def from_json(cls, text: str, where: str = "spec") -> SceneSpec:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ClutterbenchError(f"{where}: not valid JSON ({exc})") from None
        return cls.from_dict(d, where)

    def save(self, path: Path) -> None:
        write_text(Path(path), json.dumps(self.to_dict(), indent=2, sort_keys=True) + "\n")

    @classmethod
    def load(cls, path: Path) -> SceneSpec:
        path = Path(path)
        if not path.exists():
            raise ClutterbenchError(f"scene spec not found: {path}")
        if path.is_dir():
            raise ClutterbenchError(f"{path}: is a directory, not a scene spec (.json) file")
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise ClutterbenchError(f"{path}: cannot read the scene spec ({exc})") from None
        return cls.from_json(text, where=str(path))


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _kind(v: Any) -> str:
    """What a JSON value is, for an error message."""
    if isinstance(v, bool):
        return f"true/false ({str(v).lower()})"
    if v is None:
        return "null"
    if isinstance(v, dict):
        return "an object"
    if isinstance(v, list):
        return f"a list of {len(v)}"
    return f"{'a string' if isinstance(v, str) else 'a number'} ({v!r})"


def _check_vector(v: Any, n: int, what: str, where: str) -> None:
    if not (isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)):
        got = _kind(v)
        if isinstance(v, list) and len(v) == n:
            got = f"{_kind(next(x for x in v if not _is_number(x)))} in the list"
        raise ClutterbenchError(f"{where}: expected a list of {n} numbers {what}, got {got}")


def check_spec_dict(d: Any, where: str = "spec") -> tuple[Shelf, CameraConfig]:
    """Check the JSON form of a spec key by key (docs/spec-format.md): one ClutterbenchError
    naming the key (and the box) for a key that is unknown or missing, or of the wrong type or
    shape; returns the parsed shelf and camera. What the boxes' values mean is
    `validate_spec`'s to check."""
    if not isinstance(d, dict):
        raise ClutterbenchError(f"{where}: a scene spec must be a JSON object, got {_kind(d)}")
    unknown = sorted(set(d) - set(SPEC_KEYS))
    if unknown:
        raise ClutterbenchError(
            f"{where}: unknown key '{unknown[0]}' (allowed: {', '.join(SPEC_KEYS)})"
        )
    for key in REQUIRED_KEYS:
        if key not in d:
            raise ClutterbenchError(f"{where}: missing key '{key}'")
    if d["version"] != SPEC_VERSION or isinstance(d["version"], bool):
        raise ClutterbenchError(f"{where}: unsupported spec version {d['version']!r}")
    family = d.get("family", "custom")
    if not isinstance(family, str) or family not in SPEC_FAMILIES:
        raise ClutterbenchError(
            f"{where}: family: {family!r} is not one of {', '.join(SPEC_FAMILIES)}"
        )
    if not isinstance(d.get("meta", {}), dict):
        raise ClutterbenchError(f"{where}: meta: expected an object, got {_kind(d['meta'])}")
    shelf = parse(Shelf, d["shelf"], f"{where}: shelf")  # unknown keys, types
    for f in dataclasses.fields(Shelf):
        v = getattr(shelf, f.name)
        if not (math.isfinite(v) and v > 0):
            raise ClutterbenchError(f"{where}: shelf.{f.name}: {v!r} m must be positive")
    camera = parse(CameraConfig, d["camera"], f"{where}: camera")  # unknown keys, types, ranges
    boxes = d["boxes"]
    if not isinstance(boxes, list):
        raise ClutterbenchError(f"{where}: boxes: expected a list of boxes, got {_kind(boxes)}")
    if not boxes:
        raise ClutterbenchError(f"{where}: boxes: the list is empty (a scene needs a box)")
    for k, box in enumerate(boxes):
        at = f"{where}: box {k}"
        if not isinstance(box, dict):
            raise ClutterbenchError(f"{at}: expected an object, got {_kind(box)}")
        unknown = sorted(set(box) - set(BOX_KEYS))
        if unknown:
            raise ClutterbenchError(
                f"{at}: unknown key '{unknown[0]}' (allowed: {', '.join(BOX_KEYS)})"
            )
        for key in ("size_m", "pose"):
            if key not in box:
                raise ClutterbenchError(f"{at}: missing key '{key}'")
        _check_vector(box["size_m"], 3, "[depth x, width y, height z] (m)", f"{at}: size_m")
        _check_vector(box["pose"], 7, "[x, y, z, qw, qx, qy, qz]", f"{at}: pose")
        t = box.get("type", 0)
        if isinstance(t, bool) or not isinstance(t, int) or t < 0:
            raise ClutterbenchError(
                f"{at}: type: expected a catalogue index (an integer >= 0), got {_kind(t)}"
            )
        if not _is_number(box.get("density_kg_m3", 1.0)):
            raise ClutterbenchError(
                f"{at}: density_kg_m3: expected a number, got {_kind(box['density_kg_m3'])}"
            )
    return shelf, camera


def validate_spec(
    spec: SceneSpec, where: str = "spec", memo: dict[bytes, float] | None = None
) -> SceneSpec:
    """The spec with near-unit quaternions normalized; a ClutterbenchError naming the box for
    anything a world cannot hold. `memo`: pair depths already measured (deepest_overlap)."""
    poses = spec.poses.copy()
    for k in range(spec.n):
        box = f"{where}: box {k}"
        if not (np.all(np.isfinite(spec.sizes_m[k])) and np.all(np.isfinite(poses[k]))):
            raise ClutterbenchError(f"{box} has a NaN or infinite size or pose")
        if np.any(spec.sizes_m[k] <= 0):
            raise ClutterbenchError(f"{box}: size {spec.sizes_m[k].tolist()} m must be positive")
        if spec.densities_kg_m3 is not None and not spec.densities_kg_m3[k] > 0:
            if not np.isnan(spec.densities_kg_m3[k]):
                raise ClutterbenchError(f"{box}: density must be positive")
        norm = float(np.linalg.norm(poses[k, 3:]))
        if abs(norm - 1.0) > QUAT_NORM_TOL:
            raise ClutterbenchError(
                f"{box}: quaternion {poses[k, 3:].tolist()} has length {norm:.4g}, not 1"
            )
        if abs(norm - 1.0) > _QUAT_EXACT_TOL:
            poses[k, 3:] /= norm
        if not spec.shelf.contains(poses[k, :3])[0]:
            raise ClutterbenchError(
                f"{box}: centre {np.round(poses[k, :3], 4).tolist()} m is outside the shelf"
            )
    overlap = deepest_overlap(spec.sizes_m, poses, memo)
    if overlap is not None:
        a, b, depth = overlap
        raise ClutterbenchError(
            f"{where}: boxes {a} and {b} interpenetrate by {depth * 1000:.1f} mm"
        )
    return dataclasses.replace(spec, poses=poses)


def deepest_overlap(
    sizes_m: np.ndarray, poses: np.ndarray, memo: dict[bytes, float] | None = None
) -> tuple[int, int, float] | None:
    """(a, b, depth) of the most deeply interpenetrating pair of boxes if it is deeper than
    MAX_PENETRATION_M, else None. `memo`: the depths of pairs already measured, by the two
    boxes' sizes and poses (a caller that moves a few boxes at a time passes the same dict
    again: an unmoved pair's depth is not measured twice, and is the same number)."""
    half = np.array([box_aabb_half_extents(s, p[3:]) for s, p in zip(sizes_m, poses)])
    worst = None
    for a in range(len(sizes_m)):
        for b in range(a + 1, len(sizes_m)):
            gap = np.abs(poses[a, :3] - poses[b, :3]) - half[a] - half[b]
            if np.any(gap > -MAX_PENETRATION_M):  # AABBs barely meet: cannot overlap deeper
                continue
            key = b"".join(x.tobytes() for x in (sizes_m[a], poses[a], sizes_m[b], poses[b]))
            depth = memo.get(key) if memo is not None else None
            if depth is None:
                depth = obb_penetration_m(  # a pair no deeper than the limit: not asked how deep
                    poses[a, :3],
                    poses[a, 3:],
                    sizes_m[a],
                    poses[b, :3],
                    poses[b, 3:],
                    sizes_m[b],
                    shallow_m=MAX_PENETRATION_M,
                )
                if memo is not None:
                    memo[key] = depth
            if depth > MAX_PENETRATION_M and (worst is None or depth > worst[2]):
                worst = (a, b, depth)
    return worst
