"""Each collapse-table row says how our settings differ from the thesis'."""

from __future__ import annotations

import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import load_thesis_figures
from clutterbench.report.tables_5_1_6_1 import settings_differences, thesis_settings

OURS = {
    "image_size": 128,
    "encoder_width": 0.25,
    "imagenet_pretrained": False,
    "lr": 0.001,
    "epochs": 6,
    "lr_schedule": "cosine",
    "batch_size": 32,
    "loss": "bce",
}


def test_differences_name_ours_and_the_thesis_value_and_skip_what_matches():
    thesis = {"image_size": 256, "encoder_width": 1.0, "lr": 1e-4, "batch_size": 32}
    assert settings_differences(OURS, thesis) == (
        "128 px (thesis 256); VGG width 0.25 (thesis 1.0); lr 0.001 (thesis 0.0001)"
    )
    assert settings_differences(OURS, {"lr": 0.001, "loss": "bce"}) == "none"
    assert settings_differences(OURS, {"imagenet_pretrained": True}) == (
        "from scratch (thesis ImageNet-pretrained)"
    )


def test_row_settings_override_the_table_and_null_means_not_stated():
    figures = {
        "t": {
            "settings": {"batch_size": 32, "lr": 1e-4, "test_images": 1000},
            "rows": [{"row": "a", "settings": {"batch_size": 16, "lr": None}}],
        }
    }
    assert thesis_settings(figures, "t", "a") == {"batch_size": 16, "test_images": 1000}
    figures["t"]["settings"]["lr_decay"] = 0.1
    with pytest.raises(ClutterbenchError, match="t settings.lr_decay: unknown setting"):
        thesis_settings(figures, "t", "a")


@pytest.mark.parametrize("table", ["table_5_1", "table_6_1", "table_4_2"])
def test_every_row_of_the_thesis_tables_has_readable_settings(root, table):
    figures = load_thesis_figures(root / "reports/thesis_figures.yaml")
    for row in figures[table]["rows"]:
        settings = thesis_settings(figures, table, row["row"])
        assert {"image_size", "encoder_width", "batch_size", "test_images"} <= set(settings)
        assert settings_differences(OURS, settings)  # every known key formats
