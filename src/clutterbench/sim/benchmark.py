"""Benchmark scenes: the settled starts (and targets) of every table's test streams, made once
by an explicit command (`make benchmark-scenes`, cli/benchmark_scenes.py) and read by every stage,
environment and agent evaluation, so that episode i starts from the same bytes on any CPU.

Settling a drawn placement is physics, and PhysX differs in the last bits across CPUs: drawn
live, a trial's start (and so its target) differs between machines. Read from the artifact,
only the physics of the actions does.

The artifact, data/benchmark/ (committed with the code):

    <stream>.jsonl   one entry per line: {"key", "kind", "stream", "index", "value"}
    manifest.json    every file's sha256 and entry count, and how the entries were made

An entry's key is a digest of everything its draw depends on (seed, stream, index, the
stream's families / box counts / catalogue, physics, camera, attempts, ...): a draw whose
inputs match an entry reads it, any other (a swept stream, a custom scene, a scale beyond the
artifact) is drawn live, as before, and its record says so (`scene_source`). params.yaml pins
the manifest's sha256 (`benchmark.manifest_sha256`); a manifest that does not match the pin,
or a file that does not match the manifest, is a one-line error: regenerating the artifact
changes results only once its new hash is committed.

    key, value = lookup("settled", fields)      # value None: not in the artifact
    with recording() as entries: ...            # the generator: draw live, keep each draw
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.config import load_params, project_params_path
from clutterbench.errors import ClutterbenchError

DIR = Path("data/benchmark")
"""The artifact, relative to the project root."""
MANIFEST = "manifest.json"
ENV = "CLUTTERBENCH_BENCHMARK"
"""Set to `off` to draw every start live (what the generator does)."""
PIN = "benchmark.manifest_sha256"


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"benchmark key: cannot serialise {type(value).__name__}")


def entry_key(kind: str, fields: Mapping[str, Any]) -> str:
    """The digest naming a draw of `kind` with inputs `fields` (floats exactly, by repr)."""
    text = json.dumps(dict(fields), sort_keys=True, default=_plain)
    return hashlib.sha256(f"{kind}\n{text}".encode()).hexdigest()[:32]


def scene_hash(spec: Any) -> str:
    """A settled spec's name in records: the sha256 of its canonical JSON (16 hex digits)."""
    return hashlib.sha256(spec.to_json().encode()).hexdigest()[:16]


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@dataclasses.dataclass
class Store:
    entries: dict[str, Any]
    scenes: frozenset[str]
    """scene_hash of every stored spec."""
    root: Path | None


_STORE: Store | None = None
_RECORDING: list[dict[str, Any]] | None = None


def project_root() -> Path | None:
    try:
        return project_params_path().parent
    except ClutterbenchError:
        return None


def load_store(root: Path | None) -> Store:
    """The artifact under `root` checked against its manifest and the params' pin; empty when
    the params pin nothing."""
    if root is None:
        return Store({}, frozenset(), None)
    pin = (load_params(root / "params.yaml").get("benchmark") or {}).get("manifest_sha256")
    if pin is None:
        return Store({}, frozenset(), root)
    if not (isinstance(pin, str) and len(pin) == 64 and set(pin) <= set("0123456789abcdef")):
        raise ClutterbenchError(f"{PIN}: {pin!r} is not a sha256 (64 hex digits) or null")
    where = root / DIR
    manifest_path = where / MANIFEST
    if not manifest_path.is_file():
        raise ClutterbenchError(
            f"{DIR}/{MANIFEST} missing (params.yaml pins {PIN}): restore it with "
            f"`git checkout -- {DIR}` or regenerate it with `make benchmark-scenes`"
        )
    digest = file_sha256(manifest_path)
    if digest != pin:
        raise ClutterbenchError(
            f"{DIR}/{MANIFEST}: sha256 {digest[:16]}..., params.yaml pins {str(pin)[:16]}...: "
            f"commit the new pin ({PIN}) if you regenerated the scenes on purpose, else "
            f"`git checkout -- {DIR}`"
        )
    manifest = json.loads(manifest_path.read_text())
    entries: dict[str, Any] = {}
    scenes: set[str] = set()
    for name, about in manifest["files"].items():
        path = where / name
        if not path.is_file() or file_sha256(path) != about["sha256"]:
            raise ClutterbenchError(
                f"{DIR}/{name}: missing or not the file its manifest names (corrupt?): "
                f"`git checkout -- {DIR}`"
            )
        for line in path.read_text().splitlines():
            entry = json.loads(line)
            entries[entry["key"]] = entry["value"]
            if isinstance(entry["value"], dict) and "scene_hash" in entry["value"]:
                scenes.add(entry["value"]["scene_hash"])
    return Store(entries, frozenset(scenes), root)


def store() -> Store:
    """This process's artifact (loaded once; re-read when the working directory's project
    changes)."""
    global _STORE
    root = project_root()
    if _STORE is None or _STORE.root != root:
        _STORE = load_store(root)
    return _STORE


def active() -> bool:
    return _RECORDING is None and os.environ.get(ENV, "") != "off"


def lookup(kind: str, fields: Mapping[str, Any]) -> tuple[str, Any | None]:
    """(key, stored value) of a draw, value None when it is not in the artifact (or while
    recording, or with CLUTTERBENCH_BENCHMARK=off)."""
    key = entry_key(kind, fields)
    if not active():
        return key, None
    return key, store().entries.get(key)


def remember(key: str, kind: str, stream: str, index: int, value: Any) -> None:
    """Keep a live draw while the generator records (no-op otherwise)."""
    if _RECORDING is not None:
        _RECORDING.append(
            {"key": key, "kind": kind, "stream": stream, "index": int(index), "value": value}
        )


@contextlib.contextmanager
def recording() -> Iterator[list[dict[str, Any]]]:
    """Draw every start live and collect the draws (the generator's jobs)."""
    global _RECORDING
    before, _RECORDING = _RECORDING, []
    try:
        yield _RECORDING
    finally:
        _RECORDING = before


def source_of(hash_: str) -> str:
    """'benchmark' when the start named `hash_` is one of the artifact's, else 'drawn'."""
    if not active():
        return "drawn"
    return "benchmark" if hash_ in store().scenes else "drawn"


def scene_fields(spec: Any) -> dict[str, str]:
    """A record's names for its settled start: its hash and where it came from."""
    h = scene_hash(spec)
    return {"scene": h, "scene_source": source_of(h)}
