"""Atomic, deterministic file writing: temp file then rename, fixed zip timestamps."""

from __future__ import annotations

import io
import json
import os
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from clutterbench.errors import ClutterbenchError

# Fixed zip entry time so that the same arrays give byte-identical shards (np.savez stamps
# the current time into every entry).
_ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temp path beside `path`; rename it over `path` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_json(path: Path, obj: object) -> None:
    write_text(path, json.dumps(obj, indent=2, sort_keys=True) + "\n")


def read_json(path: Path) -> object:
    path = Path(path)
    if not path.exists():
        raise ClutterbenchError(f"missing file {path}")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ClutterbenchError(f"corrupt JSON in {path}: {exc}") from None


def save_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """np.savez_compressed, but byte-identical for identical arrays, and atomic."""
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            for key in sorted(arrays):
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.asarray(arrays[key]), allow_pickle=False)
                info = zipfile.ZipInfo(f"{key}.npy", date_time=_ZIP_EPOCH)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, buf.getvalue(), compresslevel=6)


def load_npz(path: Path, keys: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Load the arrays `keys` (all if None) of an .npz into memory; the others stay
    compressed on disk. Corrupt or missing files and missing keys raise one line."""
    path = Path(path)
    if not path.exists():
        raise ClutterbenchError(f"missing data file {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in keys or () if k not in z.files]
            if missing:
                raise ClutterbenchError(f"data file {path} holds no array '{missing[0]}'")
            return {k: z[k] for k in (z.files if keys is None else keys)}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise ClutterbenchError(f"corrupt data file {path}: {exc}") from None


def npz_names(path: Path) -> list[str]:
    """Names of the arrays in an .npz, without decompressing any."""
    path = Path(path)
    if not path.exists():
        raise ClutterbenchError(f"missing data file {path}")
    try:
        with zipfile.ZipFile(path) as zf:
            return [n.removesuffix(".npy") for n in zf.namelist() if n.endswith(".npy")]
    except (zipfile.BadZipFile, OSError) as exc:
        raise ClutterbenchError(f"corrupt data file {path}: {exc}") from None
