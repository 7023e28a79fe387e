"""The published test set's pins: its manifest.json names the sha256 of every other file of
the set, the loader included (`files`), so a changed array file or a changed loader is one
line, not a quiet score on other bytes. `clutterbench publish-testset` writes the pins; the
manifest's own `sha256` (of scenes.npz, what scorecards quote) is unchanged by them."""

from __future__ import annotations

import hashlib
from pathlib import Path

from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json

MANIFEST = "manifest.json"


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def pinned_files(root: Path) -> list[Path]:
    """Every file of the set a manifest pins: all but the manifest itself."""
    return sorted(p for p in root.iterdir() if p.is_file() and p.name != MANIFEST)


def pin_files(root: Path) -> dict[str, str]:
    """Write manifest `files`: file name -> sha256 of every file of the set; returns them."""
    manifest = read_json(root / MANIFEST)
    files = {p.name: file_sha256(p) for p in pinned_files(root)}
    if files.get("scenes.npz") != manifest.get("sha256"):
        raise ClutterbenchError(f"{root}/scenes.npz: its sha256 is not the manifest's")
    write_json(root / MANIFEST, manifest | {"files": files})
    return files


def pin_problems(root: Path) -> list[str]:
    """Each way the set's files differ from its manifest's pins (none when it pins nothing)."""
    files = read_json(root / MANIFEST).get("files")
    if files is None:
        return []
    found = {p.name: p for p in pinned_files(root)}
    out = [f"{name}: pinned, missing" for name in sorted(set(files) - set(found))]
    out += [f"{name}: not pinned" for name in sorted(set(found) - set(files))]
    out += [
        f"{name}: sha256 {file_sha256(found[name])[:12]}, pinned {sha[:12]}"
        for name, sha in sorted(files.items())
        if name in found and file_sha256(found[name]) != sha
    ]
    return out


def check_pins(root: Path) -> None:
    """One line when a file of the set is not the one its manifest pins."""
    problems = pin_problems(root)
    if problems:
        raise ClutterbenchError(f"{root}: not the files its manifest pins ({'; '.join(problems)})")
