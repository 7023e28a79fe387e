"""Per-epoch / per-trial rows as CSV (read by `dvc plots`), appended one line per row."""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from pathlib import Path

from clutterbench.io import write_text


class CsvLog:
    """Rows with fixed columns. Opening the log starts a fresh file (header only); each row
    is then appended and flushed, so a crashed run leaves every finished row on disk and a
    long log costs one line per row, not a rewrite of the whole file."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path, self.columns = Path(path), list(columns)
        write_text(self.path, self._line(dict(zip(self.columns, self.columns))))

    def append(self, row: Mapping[str, object]) -> None:
        extra = set(row) - set(self.columns)
        if extra:
            raise KeyError(f"{self.path.name}: unknown columns {sorted(extra)}")
        line = self._line({c: row.get(c, "") for c in self.columns})
        with self.path.open("a", newline="") as f:
            f.write(line)
            f.flush()

    def _line(self, row: Mapping[str, object]) -> str:
        buf = io.StringIO()
        csv.DictWriter(buf, fieldnames=self.columns, lineterminator="\n").writerow(row)
        return buf.getvalue()
