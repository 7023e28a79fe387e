"""Fresh pull-consequence scenes (`clutterbench evaluate-predictor --fresh N`, `clutterbench
evaluate-agent --fresh N`): which scenes, and from which seed streams. They are drawn and
labelled by support/testset_fresh.py, with the code that builds the test set.

The published test set holds its own labels, so a predictor scored on it could have read them:
its score is on trust. A fresh set's scenes did not exist when the predictor was written.

Seed streams (why a fresh scene is never a dataset, benchmark or published scene): every
scene stream of this project is numpy's default_rng([seed, crc32(key), index, ...]) with seed
= base.seed (params.yaml) and key a dataset name or "trials/<stream>". A fresh set draws with

- seed = stream_seed(S): the first 63 bits of sha256("clutterbench/fresh/<S>"), a tag mixed
  into the user-facing seed S, checked here to differ from base.seed;
- keys in a namespace of their own, "fresh/<dataset>" and "trials/fresh/<stream>", checked here
  to be no dataset's or stream's name and to differ from theirs under crc32.

Either alone keeps the streams apart; both hold. S is drawn from os.urandom unless given, and
printed and recorded with every row scored on it."""

from __future__ import annotations

import hashlib
import secrets
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.errors import ClutterbenchError

TAG = "fresh"
"""The stream tag: mixed into the seed and the first part of every fresh key."""
SEED_BITS = 63
BENCHMARK = "benchmark:"
"""A test-set source that is a trials stream's starts (data.testset: `source` array)."""


def draw_seed(given: int | None) -> tuple[int, str]:
    """(S, where it came from): `given`, else 63 random bits from the OS."""
    if given is not None:
        if given < 0:
            raise ClutterbenchError(f"--seed {given}: a seed is an integer >= 0")
        return int(given), "given"
    return secrets.randbits(SEED_BITS), "os.urandom"


def stream_seed(seed: int) -> int:
    """The seed the fresh scenes of user seed `seed` are drawn with (module doc)."""
    digest = hashlib.sha256(f"clutterbench/{TAG}/{int(seed)}".encode()).digest()
    return int.from_bytes(digest[:8], "big") >> (64 - SEED_BITS)


def fresh_name(name: str) -> str:
    """A source's fresh stream name: "fresh/<dataset>" or, for a trials stream, "fresh/<stream>"
    (its key is then "trials/fresh/<stream>")."""
    return f"{TAG}/{name}"


def project_keys(params: Mapping[str, Any]) -> set[str]:
    """The scene-stream keys the project's datasets and trials streams draw with (their setup
    and target streams included)."""
    datasets = ((params.get("generate") or {}).get("datasets") or {}).keys()
    streams = ((params.get("trials") or {}).get("streams") or {}).keys()
    keys = {k for d in datasets for k in (d, f"{d}/setup")}
    for s in streams:
        keys |= {f"trials/{s}", f"trials/{s}/setup", f"trials/{s}/target"}
    return keys | {"trials/support", "trials/support/setup"}


def check_apart(params: Mapping[str, Any], base_seed: int, seed: int, names: list[str]) -> None:
    """Refuse fresh streams that could meet a project stream (module doc): the seeds differ,
    and no fresh key is a project key or shares its crc32."""
    if stream_seed(seed) == base_seed:
        raise ClutterbenchError(f"fresh seed {seed}: its stream seed is base.seed; draw another")
    mine = set()
    for name in names:
        key = fresh_name(name)
        mine |= {key, f"{key}/setup", f"trials/{key}", f"trials/{key}/setup"}
        mine |= {f"trials/{key}/target"}
    theirs = project_keys(params)
    crc = {zlib.crc32(k.encode()): k for k in theirs}
    for key in sorted(mine):
        if key in theirs or zlib.crc32(key.encode()) in crc:
            other = crc.get(zlib.crc32(key.encode()), key)
            raise ClutterbenchError(f"fresh stream {key} meets the project's stream {other}")


def allocate(sources: Mapping[str, int], n: int) -> dict[str, int]:
    """N scenes over the reference set's sources in its proportions (largest remainder; ties to
    the source listed first): a fresh set mixes scene kinds as the published one does."""
    if n < 1:
        raise ClutterbenchError(f"--fresh {n}: draw at least one scene")
    total = sum(sources.values())
    if not total:
        raise ClutterbenchError("the reference test set lists no sources to draw fresh scenes of")
    share = {s: n * c / total for s, c in sources.items()}
    out = {s: int(v) for s, v in share.items()}
    by_rest = sorted(share, key=lambda s: -(share[s] - out[s]))
    for s in by_rest[: n - sum(out.values())]:
        out[s] += 1
    return {s: k for s, k in out.items() if k}


def check_camera(reference: Mapping[str, Any], camera: Any, where: Path) -> None:
    """Fresh scenes are rendered with params' sim.camera: refuse one that is not the camera
    of the reference set (its images would not be comparable)."""
    from clutterbench.data.testset import camera_matrix

    ref = reference["camera"]
    same = ref.get("image_size") == camera.image_size and np.allclose(
        np.asarray(ref["K"]), np.asarray(camera_matrix(camera))
    )
    if not same:
        raise ClutterbenchError(
            f"{where}: rendered at {ref.get('image_size')} px, sim.camera at "
            f"{camera.image_size} px (or another field of view): run with the params of the "
            "scale that made it (base.scale)"
        )


def load_reference(path: Path) -> dict[str, Any]:
    """The reference test set's manifest (its sources, thresholds, camera)."""
    from clutterbench.io import read_json

    manifest = read_json(path / "manifest.json")
    missing = [k for k in ("sources", "thresholds", "min_pixels", "camera") if k not in manifest]
    if missing:
        raise ClutterbenchError(f"{path}/manifest.json lacks {', '.join(missing)}")
    return manifest
