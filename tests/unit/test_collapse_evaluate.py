"""The threshold reported beside the params one is never chosen on the test set."""

from __future__ import annotations

from pathlib import Path

import pytest

from clutterbench.collapse.evaluate import SplitRef, check_val_split
from clutterbench.errors import ClutterbenchError


def ref(dataset: str, split: str) -> SplitRef:
    return SplitRef(dataset, Path(f"data/split/{dataset}.json"), split, 0.005)


def test_val_split_of_the_evaluated_or_the_training_dataset_is_accepted():
    check_val_split(ref("ch5", "test"), ref("ch5", "val"), "ch5", "key")
    check_val_split(ref("ch6_test", "test"), ref("ch6", "val"), "ch6", "key")


def test_choosing_on_the_evaluated_split_or_an_unrelated_dataset_is_refused():
    with pytest.raises(ClutterbenchError, match="key: would choose the threshold on the eval"):
        check_val_split(ref("ch5", "val"), ref("ch5", "val"), "ch5", "key")
    with pytest.raises(ClutterbenchError, match="neither the evaluated dataset 'ch6_test'"):
        check_val_split(ref("ch6_test", "test"), ref("ch4_same", "val"), "ch5", "key")
