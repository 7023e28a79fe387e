"""Per-epoch / per-trial rows as CSV (read by `dvc plots`); rewritten atomically per row."""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from pathlib import Path

from clutterbench.io import write_text


class CsvLog:
    """Rows with fixed columns; the file on disk is always complete (temp file + rename)."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path, self.columns = Path(path), list(columns)
        self.rows: list[dict[str, object]] = []

    def append(self, row: Mapping[str, object]) -> None:
        extra = set(row) - set(self.columns)
        if extra:
            raise KeyError(f"{self.path.name}: unknown columns {sorted(extra)}")
        self.rows.append({c: row.get(c, "") for c in self.columns})
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=self.columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(self.rows)
        write_text(self.path, buf.getvalue())
