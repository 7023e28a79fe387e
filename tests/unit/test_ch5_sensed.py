"""Table 5.2 under a depth sensor (trials.ch5_sensed): the sensed conditions params.yaml adds,
a ch. 5 episode whose planner sees through the sensor while the harness (free places,
execution and judging, the oracle) reads the exact picture, and the table's sensed rows."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import clutterbench.trials.ch5.episodes as ch5
import clutterbench.trials.ch5.perception as ch5_perception
from clutterbench.config import load_base, load_params, load_section
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.planning.ch5.replenish import ReplenishPlanner
from clutterbench.report.config import ReportConfig
from clutterbench.report.table_5_2 import table_5_2
from clutterbench.report.tables import load_thesis_figures
from clutterbench.sim.config import CameraConfig, PhysicsConfig, SimConfig
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe, sensed
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import Ch5ConditionConfig, SceneStreamConfig, TrialsConfig

ROOT = Path(__file__).resolve().parents[2]
PARAMS = load_params(ROOT / "params.yaml")
FIGURES = load_thesis_figures(ROOT / load_section(ReportConfig, "report", PARAMS).thesis_figures)
CAM = CameraConfig(image_size=64)
STANDING = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # width up, thickness across
NEW_BOX = np.array([0.1, 0.12, 0.03])


# -- the sensed conditions -------------------------------------------------------------------
def test_each_named_ch5_condition_runs_again_under_the_sensor_with_its_own_perception():
    cfg = load_section(TrialsConfig, "trials", PARAMS)
    twin = cfg.ch5_conditions["replenish_stacked_d415"]
    assert (twin.planner, twin.perception, twin.sensing) == ("replenish", "detector", "d415")
    assert twin == dataclasses.replace(cfg.ch5_conditions["replenish_stacked"], sensing="d415")
    assert cfg.ch5_conditions["replenish_stacked"].sensing == "ideal"
    added = {n for n, c in cfg.ch5_conditions.items() if c.sensing != "ideal"}
    assert added == {f"{n}_{cfg.ch5_sensed.sensing}" for n in cfg.ch5_sensed.of}
    # Table 5.2's sensed rows are exactly those conditions'
    rows = cfg.ch5_sensed.table_rows(load_section(ReportConfig, "report", PARAMS).table_5_2)
    sensed_rows = {row: cond for row, cond in rows.items() if row.count("/") == 2}
    assert sensed_rows["replenish/stacked/d415"] == "replenish_stacked_d415"
    assert set(sensed_rows.values()) == added


def test_a_sensed_condition_reads_the_detector_trained_on_its_sensor(tmp_path, monkeypatch):
    cfg = load_section(TrialsConfig, "trials", PARAMS)
    exact, twin = (
        cfg.ch5_conditions["replenish_stacked"],
        cfg.ch5_conditions["replenish_stacked_d415"],
    )
    assert ch5.detector_path(exact) == Path("models/detector/best.pt")
    assert ch5.detector_path(twin) == Path("models/detector_d415/best.pt")  # stage detector_sensed
    jobs = ch5.ch5_jobs(
        "replenish_stacked_d415",
        twin,
        trials=cfg,
        sim=load_section(SimConfig, "sim", PARAMS),
        seed=0,
        prob_threshold=0.5,
        scene_type="stacked",
    )
    assert {j.detector_path for j in jobs} == {Path("models/detector_d415/best.pt")}
    # a missing sensed detector names the stage that makes it
    monkeypatch.chdir(tmp_path)
    for name in ("detector", cfg.ch5.model):
        (tmp_path / "models" / name).mkdir(parents=True)
        (tmp_path / "models" / name / "best.pt").write_bytes(b"")
    ch5.check_models({"replenish_stacked": exact}, cfg.ch5)
    with pytest.raises(
        ClutterbenchError, match="detector_d415/best.pt missing; run the detector_sensed"
    ):
        ch5.check_models({"replenish_stacked": exact, "replenish_stacked_d415": twin}, cfg.ch5)


def test_an_unknown_ch5_sensed_name_is_one_line():
    params = copy.deepcopy(PARAMS)
    params["trials"]["ch5_sensed"]["of"] = ["replenish_stacked", "replenish_nowhere"]
    with pytest.raises(ClutterbenchError) as err:
        load_section(TrialsConfig, "trials", params)
    assert "\n" not in str(err.value)
    assert "ch5_sensed.of: no condition 'replenish_nowhere' in trials.ch5_conditions" in str(
        err.value
    )


# -- an episode under the sensor -------------------------------------------------------------
def crowded_row() -> SceneSpec:
    """Three standing boxes in a row and one more on each side of it, 1.2 cm away: every
    placement candidate is occupied, a side box can be carried toward its wall and held."""
    ys = [-0.06, 0.0, 0.06, 0.102, -0.102]
    return SceneSpec(
        sizes_m=np.tile(NEW_BOX, (5, 1)),
        poses=np.array([[0.1, y, 0.06, *STANDING] for y in ys]),
        camera=CAM,
        meta={"groups": [[0, 1, 2], [3], [4]]},
    )


def exact_picture(spec: SceneSpec):
    return observe(world_at(spec, SceneState.start(spec), PhysicsConfig(), render=True), CAM)


def ch5_job(planner: str, sensing: str, perception: str = "detector"):
    cond = Ch5ConditionConfig(
        planner=planner, stream="ch5_shelved", perception=perception, sensing=sensing
    )
    return ch5.ch5_jobs(
        "hand",
        cond,
        trials=TrialsConfig(max_attempts=5, mcap_images=True),
        sim=SimConfig(camera=CAM),
        seed=0,
        prob_threshold=0.5,
        scene_type="shelved",
        params=dataclasses.replace(TrialsConfig().ch5, oracle_budget=2),
        stream_cfg=SceneStreamConfig(families={"shelved": 1.0}, n_objects=(4, 6)),
        collapse_free=CollapseFreeConfig(),
    )[0]


@pytest.fixture
def seen_by(monkeypatch):
    """Who read which depth image during an episode: who -> [depth images]. The detector is a
    stand-in returning the start's ground-truth clusters, the collapse map network one that
    predicts no collapse; the planner, the random floor's action set, free places, execution
    and the oracle are the real code, watched."""
    spec = crowded_row()
    state = SceneState.start(spec)
    truth = ch5_perception.true_clusters(spec, state, PhysicsConfig(), exact_picture(spec))
    log: dict[str, list[np.ndarray]] = {}

    def saw(who: str, obs) -> None:
        log.setdefault(who, []).append(obs.depth_m.copy())

    class Detector:
        def detect(self, depth_m):
            log.setdefault("detector", []).append(depth_m.copy())
            return truth

    def collapse_map_fn(job):
        def collapse_map(obs, mask):
            saw("collapse map", obs)
            return np.zeros(mask.shape, np.float32)

        return collapse_map

    def watch(module, name: str, who: str, at: int):
        real = getattr(module, name)

        def spy(*args, **kwargs):
            saw(who, args[at])
            return real(*args, **kwargs)

        monkeypatch.setattr(module, name, spy)

    for path in ("models/detector/best.pt", "models/detector_d415/best.pt"):
        monkeypatch.setitem(ch5_perception._MODELS, str(Path(path)), Detector())
    monkeypatch.setattr(ch5, "collapse_map_fn", collapse_map_fn)
    watch(ch5, "free_places", "free places", 3)
    watch(ch5, "execute", "execution", 1)
    watch(ch5, "oracle_choice", "oracle", 2)
    watch(ch5, "action_set", "random's action set", 0)
    watch(ReplenishPlanner, "plan", "planner's depth points", 1)
    return spec, log


PLANNER_SIDE = ("detector", "collapse map", "planner's depth points", "random's action set")
HARNESS_SIDE = ("free places", "execution", "oracle")


@pytest.mark.parametrize(
    ("planner", "perception", "watched"),
    [
        ("replenish", "detector", {"detector", "collapse map", "planner's depth points"}),
        ("random", "detector", {"detector", "random's action set", "execution"}),
        ("oracle", "clusters", {"oracle", "execution"}),
    ],
)
def test_a_sensed_episode_s_planner_sees_the_sensed_picture_and_the_harness_the_exact_one(
    seen_by, planner, perception, watched
):
    spec, log = seen_by
    exact = exact_picture(spec)
    want = sensed(exact, "d415").depth_m
    assert not np.array_equal(want, exact.depth_m), "the sensor changed nothing: no test"
    result = ch5.replenish(spec, ch5_job(planner, "d415", perception), NEW_BOX)
    assert result.record["sensing"] == "d415"
    assert watched | {"free places"} <= set(log), f"not exercised: {watched - set(log)}"
    for who in PLANNER_SIDE:
        for depth in log.get(who, [])[:1]:  # the start's picture
            assert np.array_equal(depth, want), f"{who} did not read the sensed depth"
    for who in HARNESS_SIDE:
        for depth in log.get(who, [])[:1]:
            assert np.array_equal(depth, exact.depth_m), f"{who} did not read the exact depth"
    depths = [image for _, kind, image in result.log.events if kind == "depth"]
    assert np.array_equal(depths[0], want), "the MCAP logs what the planner saw"


def test_an_ideal_episode_keeps_its_record_and_every_reader_sees_the_exact_picture(seen_by):
    spec, log = seen_by
    exact = exact_picture(spec)
    assert sensed(exact, "ideal") is exact, "an ideal picture passes unchanged"
    result = ch5.replenish(spec, ch5_job("replenish", "ideal"), NEW_BOX)
    assert "sensing" not in result.record
    assert result.record["steps"], "the ideal planner placed or moved something"
    for who, depths in log.items():
        assert all(np.array_equal(d, exact.depth_m) for d in depths[:1]), who


def test_a_picture_with_no_return_anywhere_ends_the_episode_as_a_failure(seen_by, monkeypatch):
    """A sensed picture that defeats perception entirely (every pixel 0: no return) is no
    exception: the planner finds no cluster with depth points and gives up."""
    spec, _ = seen_by

    def blind(obs, sensing):
        return obs if sensing == "ideal" else dataclasses.replace(obs, depth_m=0 * obs.depth_m)

    monkeypatch.setattr(ch5, "sensed", blind)
    for planner in ("replenish", "random"):
        record = ch5.replenish(spec, ch5_job(planner, "d415"), NEW_BOX).record
        assert (record["end"], record["success"], record["sensing"]) == ("gave_up", False, "d415")


# -- Table 5.2's sensed rows -----------------------------------------------------------------
def _records(condition: str, wins: int, n: int = 4, sensing: str | None = None) -> list[dict]:
    out = []
    for i in range(n):
        r = {
            "condition": condition,
            "episode": i,
            "success": i < wins,
            "strict_success": i < wins,
            "n_disturbed": 0,
            "branch": "simple",
            "end": "placed" if i < wins else "collapse",
            "perception": "detector",
            "free_at_start": False,
        }
        out.append(r if sensing is None else r | {"sensing": sensing})
    return out


def _md_rows(path: Path) -> dict[str, dict[str, str]]:
    """The markdown table's rows by their first cell."""
    lines = [x for x in path.read_text().splitlines() if x.startswith("| ")]  # no |---|
    cells = [[c.strip() for c in x.strip("|").split("|")] for x in lines]
    header = cells[0]
    return {c[0]: dict(zip(header, c, strict=True)) for c in cells[1:]}


def test_a_sensed_row_is_a_method_row_of_its_own_without_thesis_figures(tmp_path):
    by_condition = {
        "replenish_stacked": _records("replenish_stacked", 3),
        "replenish_stacked_d415": _records("replenish_stacked_d415", 1, sensing="d415"),
    }
    rows = {
        "replenish/stacked": "replenish_stacked",
        "replenish/stacked/d415": "replenish_stacked_d415",
    }
    table_5_2(by_condition, rows, FIGURES, tmp_path, "tiny")
    table = _md_rows(tmp_path / "table_5_2.md")
    exact = table["with collapse prediction"]
    seen = table["with collapse prediction, D415-class sensor (d415)"]
    assert exact["stacked"].startswith("3/4") and seen["stacked"].startswith("1/4")
    assert exact["stacked (thesis)"] == "23/40 (57.5%)"
    assert seen["stacked (thesis)"] == "—" and seen["total (thesis)"] == "—"
    text = (tmp_path / "table_5_2.md").read_text()
    assert "sensed rows (trials.ch5_sensed, docs/sensing.md), by sensor preset: d415 " in text
    assert "(replenish_stacked_d415)" in text
    # alone, the exact row reads as before: no sensing note
    table_5_2(
        {"replenish_stacked": by_condition["replenish_stacked"]},
        dict(list(rows.items())[:1]),
        FIGURES,
        tmp_path / "alone",
        "tiny",
    )
    assert "sensed rows" not in (tmp_path / "alone" / "table_5_2.md").read_text()


@pytest.mark.parametrize(
    ("row", "sensing", "line"),
    [
        ("replenish/stacked/d415", "structured_light", "ran sensing structured_light, not d415"),
        ("replenish/stacked/d415", None, "ran sensing ideal, not d415"),
        ("replenish/stacked", "d415", "ran sensing d415, not ideal"),
    ],
)
def test_a_row_whose_records_saw_another_sensor_is_an_error(tmp_path, row, sensing, line):
    recs = {"cond": _records("cond", 2, sensing=sensing)}
    with pytest.raises(ClutterbenchError, match=f"report.table_5_2.{row}: .*{line}"):
        table_5_2(recs, {row: "cond"}, FIGURES, tmp_path, "tiny")


def test_the_report_adds_table_5_2_s_sensed_rows_from_trials_ch5_sensed(tmp_path, monkeypatch):
    import clutterbench.report.build as build

    report = build.Report(PARAMS, load_base(PARAMS))
    report.__dict__["figures"] = FIGURES
    twins = {f"{c}_{report.trials.ch5_sensed.sensing}" for c in report.trials.ch5_sensed.of}
    records = [
        r
        for cond in {*report.cfg.table_5_2.values(), *twins}
        for r in _records(cond, 1, sensing="d415" if cond in twins else None)
    ]
    monkeypatch.setattr(build, "read_records", lambda path: records)
    monkeypatch.setattr(build, "TABLES", tmp_path)
    build.table_5_2_replenishment(report)
    table = _md_rows(tmp_path / "table_5_2.md")
    for method in ("with collapse prediction", "without collapse prediction", "random action"):
        label = next(x for x in table if x.startswith(method) and "(d415)" not in x)
        assert f"{label}, D415-class sensor (d415)" in table
    assert not any(x.startswith("oracle") and "(d415)" in x for x in table)
