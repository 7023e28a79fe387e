"""JSON scene specs: every box's size and pose, the shelf and the camera.

Any scene can be saved and loaded alone, to regenerate, inspect or replay it. Poses are the
settled poses, so a loaded spec is already at rest.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text
from clutterbench.sim.render import CameraConfig
from clutterbench.sim.shelf import Shelf

SPEC_VERSION = 1


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
    """Free-form provenance: dataset, scene index, seed, arrangement clusters."""

    @property
    def n(self) -> int:
        return int(self.sizes_m.shape[0])

    def to_dict(self) -> dict[str, Any]:
        return {
            "version": SPEC_VERSION,
            "family": self.family,
            "shelf": dataclasses.asdict(self.shelf),
            "camera": dataclasses.asdict(self.camera),
            "boxes": [
                {"size_m": [float(v) for v in s], "pose": [float(v) for v in p]}
                for s, p in zip(self.sizes_m, self.poses)
            ],
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
            spec = cls(
                sizes_m=sizes,
                poses=poses,
                shelf=Shelf(**d.get("shelf", {})),
                camera=CameraConfig(**d.get("camera", {})),
                family=d.get("family", "custom"),
                meta=d.get("meta", {}),
            )
        except ClutterbenchError:
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise ClutterbenchError(f"{where}: malformed scene spec ({exc!r})") from None
        if np.any(sizes <= 0):
            raise ClutterbenchError(f"{where}: box sizes must be positive metres")
        return spec

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
