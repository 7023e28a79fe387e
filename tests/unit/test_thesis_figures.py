"""The one data file of thesis figures: no key may be given twice (YAML keeps the last one
silently, so a stale copy of a table would shadow or be shadowed without a word)."""

from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


class _UniqueKeys(yaml.SafeLoader):
    def construct_mapping(self, node, deep=False):
        keys = [self.construct_object(k, deep=deep) for k, _ in node.value]
        twice = sorted({str(k) for k in keys if keys.count(k) > 1})
        assert not twice, f"keys given twice at line {node.start_mark.line + 1}: {twice}"
        return super().construct_mapping(node, deep=deep)


def test_thesis_figures_give_every_key_once():
    data = yaml.load((ROOT / "reports/thesis_figures.yaml").read_text(), Loader=_UniqueKeys)
    assert {"fig_3_15", "table_5_2", "table_6_3"} <= set(data)
