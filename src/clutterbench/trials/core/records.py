"""Trial records: one JSON object per episode, stored as JSON Lines (no SAPIEN, no torch)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import atomic_path


def write_records(path: Path, records: Sequence[dict[str, Any]]) -> None:
    """JSON Lines, keys sorted: byte-identical for identical records."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_text("".join(json.dumps(r, sort_keys=True) + "\n" for r in records))


def read_records(path: Path) -> list[dict[str, Any]]:
    if not Path(path).exists():
        raise ClutterbenchError(f"trial records not found: {path} (run its trials stage)")
    out = []
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            raise ClutterbenchError(f"{path}:{n}: not a JSON record (corrupt file?)") from None
    return out
