"""Figure legends and box numbers: Fig. 4.8 (risk_figure) and Fig. 6.8 (support_figure)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from clutterbench.planning.ch4.risk import CLASSES
from clutterbench.support.figure import SupportPanel, support_figure_fig
from clutterbench.trials.ch4.figure import COLOURS, risk_figure, risk_figure_fig


def _legend_labels(fig) -> list[str]:
    return [t.get_text() for legend in fig.legends for t in legend.get_texts()]


def _texts(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes for t in ax.texts if t.get_text()]  # not arrows


@pytest.fixture
def risk_inputs():
    h, w = 24, 32
    depth = np.full((h, w), 0.7, dtype=np.float32)
    masks = np.zeros((3, h, w), dtype=bool)
    masks[0, 16:22, 4:28] = True
    masks[1, 8:16, 4:14] = True
    masks[2, 8:16, 18:28] = True
    probs = np.zeros((2, len(CLASSES), h, w), dtype=np.float32)
    probs[:, CLASSES.index("E")][:, masks[1]] = 0.9
    probs[0, CLASSES.index("S")][masks[0]] = 0.9
    probs[1, CLASSES.index("C")][masks[2]] = 0.9
    return depth, masks, probs, np.array([0.0, 0.3])


def test_risk_figure_has_a_colour_legend_and_numbers_the_boxes(risk_inputs):
    depth, masks, probs, risks = risk_inputs
    args = (depth, masks[1], ["box 0", "box 2"], probs, risks, "t")
    fig = risk_figure_fig(*args, box_masks=masks, box_labels=["0", "1", "2"])
    labels = _legend_labels(fig)
    assert labels == [
        "target outline",
        "E: extracted",
        "S: supported (held)",
        "C: predicted collapse",
        "n: box index",
    ]
    patches = fig.legends[0].get_patches()
    colours = [tuple(p.get_facecolor()[:3]) for p in patches[:3]]
    assert colours == [pytest.approx(COLOURS[c]) for c in "ESC"]  # green, blue, red
    # three panels (depth + two choices), each with the three box numbers
    assert sorted(_texts(fig)) == sorted(["0", "1", "2"] * 3)
    plt.close(fig)

    plain = risk_figure_fig(*args)  # no masks: no numbers, the colour legend all the same
    assert _texts(plain) == [] and "n: box index" not in _legend_labels(plain)
    assert "C: predicted collapse" in _legend_labels(plain)
    plt.close(plain)


def test_risk_figure_png_is_byte_identical_across_calls(tmp_path, risk_inputs):
    depth, masks, probs, risks = risk_inputs
    for name in ("a.png", "b.png"):
        risk_figure(
            tmp_path / name, depth, masks[1], ["box 0", "box 2"], probs, risks, "t",
            box_masks=masks, box_labels=["0", "1", "2"],
        )  # fmt: skip
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()


def test_support_figure_legend_names_edges_outlines_and_numbers():
    depth = np.full((32, 40), 0.6, dtype=np.float32)
    masks = np.zeros((2, 32, 40), dtype=bool)
    masks[0, 20:30, 4:36] = True
    masks[1, 8:20, 6:18] = True
    panel = SupportPanel(depth, masks, [3, 5], {(3, 5)}, {(3, 5)}, "s0")
    fig = support_figure_fig([panel], "support")
    assert _legend_labels(fig) == ["true (physics)", "inferred", "box outline", "n: box index"]
    assert "supporter X to supported Y" in fig.legends[0].get_title().get_text()
    assert sorted(_texts(fig)) == ["3", "5"]
    plt.close(fig)
