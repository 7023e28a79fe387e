"""compare.py's records -> per planner and head: success, strict success and aborts after
motion over the episodes, and each head against the first, episode by episode (McNemar's
exact test): python experiments/reports/box_head_masks/summarize.py RECORDS.jsonl ..."""

from __future__ import annotations

import json
import sys
from collections import defaultdict

from scipy.stats import binomtest


def main() -> None:
    runs: dict[tuple[str, str], dict[int, dict]] = defaultdict(dict)
    for path in sys.argv[1:]:
        for line in open(path):
            r = json.loads(line)
            runs[(r["planner"], r["label"])][r["episode"]] = r
    planners = list(dict.fromkeys(p for p, _ in runs))
    labels = list(dict.fromkeys(label for _, label in runs))
    print(
        "| planner | head masks | success | strict success | aborts after motion | "
        "vs " + labels[0] + ": won only / lost only, p |"
    )
    print("|---|---|---|---|---|---|")
    for p in planners:
        first = runs[(p, labels[0])]
        for label in labels:
            rs = runs.get((p, label))
            if not rs:
                continue
            n = len(rs)
            k = sum(r["success"] for r in rs.values())
            ks = sum(r["strict_success"] for r in rs.values())
            ab = sum(r["aborts_after_motion"] for r in rs.values())
            cell = "—"
            if label != labels[0]:
                won = sum(rs[e]["success"] and not first[e]["success"] for e in rs)
                lost = sum(first[e]["success"] and not rs[e]["success"] for e in rs)
                pv = binomtest(won, won + lost).pvalue if won + lost else 1.0
                cell = f"{won} / {lost}, p = {pv:.2g}"
            print(
                f"| {p} | {label} | {k}/{n} = {100 * k / n:.1f}% | {ks}/{n} = "
                f"{100 * ks / n:.1f}% | {ab} | {cell} |"
            )


if __name__ == "__main__":
    main()
