"""Table 6.3 under task noise (report/table_6_3_noise.py) and its column in Table 6.3."""

from __future__ import annotations

from clutterbench.report.table_6_3_noise import noise_table, noise_text
from clutterbench.trials.noise.config import NoiseConfig
from clutterbench.trials.noise.replay import survival


def _summary():
    import dataclasses

    rows = {
        "oracle": ("oracle", None, [True] * 9 + [False], [[True, False]] * 5 + [[True, True]] * 5),
        "multi_step": ("multi_step", None, [True] * 5 + [False] * 5, [[True, True]] * 10),
        "oracle_robust": ("oracle_robust", "oracle", [True] * 8 + [False] * 2, [[True, True]] * 10),
    }
    return {
        "noise": dataclasses.asdict(NoiseConfig(draws=2)),
        "conditions": {
            c: {"planner": p, "stream": "s", "robust_of": of}
            | {k: survival(nom, draws) for k in ("success", "strict_success")}
            for c, (p, of, nom, draws) in rows.items()
        },
    }


def test_the_noise_table_has_each_table_condition_then_the_robust_oracles(tmp_path):
    summary = _summary()
    raw = noise_table(
        summary, {"Oracle/3-10": "oracle", "Multi/3-10": "multi_step"}, tmp_path, "tiny"
    )
    assert list(raw["condition"]) == ["oracle", "multi_step", "oracle_robust"]
    text = (tmp_path / "table_6_3_noise.md").read_text()
    # the oracle keeps 13 of its 18 (success, draw) pairs: 5 x 1 + 4 x 2
    assert "9/10 = 90.0%" in text and "72.2%" in text
    assert (tmp_path / "table_6_3_noise.png").exists()


def test_a_conditions_task_noise_cell_says_mean_spread_and_kept():
    s = survival([True, False], [[True, False], [True, True]])
    assert noise_text(s) == "75.0% ± 35.4 (50.0% kept)"
