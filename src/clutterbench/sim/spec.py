"""JSON scene specs: every box's size and pose, the shelf and the camera.

Any scene can be saved and loaded alone, to regenerate, inspect or replay it. Poses are the
settled poses, so a loaded spec is already at rest. A loaded spec is validated: a box that
is not finite, has no size, a non-unit rotation, a centre outside the shelf or overlaps
another box stops with one line naming it.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text
from clutterbench.sim.config import CameraConfig
from clutterbench.sim.geometry import box_aabb_half_extents, obb_penetration_m
from clutterbench.sim.shelf import Shelf

SPEC_VERSION = 1
MAX_PENETRATION_M = 0.001
"""Two boxes overlapping deeper than this cannot both be where the spec puts them."""
QUAT_NORM_TOL = 1e-3
"""A quaternion within this of unit length is normalized; further off, the spec is refused."""
_QUAT_EXACT_TOL = 1e-6  # float32 round-off: left untouched so replays stay bit-identical


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
    def from_dict(cls, d: dict[str, Any], where: str = "spec") -> SceneSpec:
        try:
            if d.get("version") != SPEC_VERSION:
                raise ClutterbenchError(f"{where}: unsupported spec version {d.get('version')!r}")
            boxes = d["boxes"]
            sizes = np.array([b["size_m"] for b in boxes], dtype=np.float64).reshape(-1, 3)
            poses = np.array([b["pose"] for b in boxes], dtype=np.float64).reshape(-1, 7)
            types = np.array([int(b.get("type", -1)) for b in boxes], dtype=np.int64)
            dens = np.array([float(b.get("density_kg_m3", np.nan)) for b in boxes])
            spec = cls(
                sizes_m=sizes,
                poses=poses,
                shelf=Shelf(**d.get("shelf", {})),
                camera=CameraConfig(**d.get("camera", {})),
                family=d.get("family", "custom"),
                meta=d.get("meta", {}),
                type_ids=types if np.any(types >= 0) else None,
                densities_kg_m3=dens if not np.all(np.isnan(dens)) else None,
            )
        except ClutterbenchError:
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise ClutterbenchError(f"{where}: malformed scene spec ({exc!r})") from None
        return validate_spec(spec, where)

    @classmethod
    def from_json(cls, text: str, where: str = "spec") -> SceneSpec:
        try:
            return cls.from_dict(json.loads(text), where)
        except json.JSONDecodeError as exc:
            raise ClutterbenchError(f"{where}: not valid JSON ({exc})") from None

    def save(self, path: Path) -> None:
        write_text(Path(path), json.dumps(self.to_dict(), indent=2, sort_keys=True) + "\n")

    @classmethod
    def load(cls, path: Path) -> SceneSpec:
        path = Path(path)
        if not path.exists():
            raise ClutterbenchError(f"scene spec not found: {path}")
        return cls.from_json(path.read_text(), where=str(path))


def validate_spec(spec: SceneSpec, where: str = "spec") -> SceneSpec:
    """The spec with near-unit quaternions normalized; a ClutterbenchError naming the box for
    anything a world cannot hold."""
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
    overlap = deepest_overlap(spec.sizes_m, poses)
    if overlap is not None:
        a, b, depth = overlap
        raise ClutterbenchError(
            f"{where}: boxes {a} and {b} interpenetrate by {depth * 1000:.1f} mm"
        )
    return dataclasses.replace(spec, poses=poses)


def deepest_overlap(sizes_m: np.ndarray, poses: np.ndarray) -> tuple[int, int, float] | None:
    """(a, b, depth) of the most deeply interpenetrating pair of boxes if it is deeper than
    MAX_PENETRATION_M, else None."""
    half = np.array([box_aabb_half_extents(s, p[3:]) for s, p in zip(sizes_m, poses)])
    worst = None
    for a in range(len(sizes_m)):
        for b in range(a + 1, len(sizes_m)):
            gap = np.abs(poses[a, :3] - poses[b, :3]) - half[a] - half[b]
            if np.any(gap > -MAX_PENETRATION_M):  # AABBs barely meet: cannot overlap deeper
                continue
            depth = obb_penetration_m(
                poses[a, :3], poses[a, 3:], sizes_m[a], poses[b, :3], poses[b, 3:], sizes_m[b]
            )
            if depth > MAX_PENETRATION_M and (worst is None or depth > worst[2]):
                worst = (a, b, depth)
    return worst
