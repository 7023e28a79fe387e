"""Episode jobs are frozen dataclasses: each chapter's pickles and round-trips (worker
processes and Ray receive them pickled), and a misspelt field is refused at construction."""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path

import pytest

from clutterbench.planning.ch6.support import SupportParams
from clutterbench.sim.config import CameraConfig, SimConfig
from clutterbench.trials.ch3.config import Ch3Config
from clutterbench.trials.ch3.games import Ch3Job, ch3_jobs
from clutterbench.trials.ch4.episodes import Ch4Job, ch4_jobs
from clutterbench.trials.ch5.episodes import Ch5Job, ch5_jobs
from clutterbench.trials.ch6.episodes import Ch6Job, ch6_jobs
from clutterbench.trials.config import (
    Ch4ConditionConfig,
    Ch5ConditionConfig,
    ConditionConfig,
    SceneStreamConfig,
    TrialsConfig,
)
from clutterbench.trials.core.jobs import EpisodeJob, ShelfJob

STREAM = SceneStreamConfig(families={"stacked": 1}, n_objects=(3, 5))
TRIALS = TrialsConfig(streams={"s": STREAM}, max_attempts=30)
SCENE = {"trials": TRIALS, "sim": SimConfig(camera=CameraConfig(image_size=64)), "seed": 0}


def _jobs() -> dict[type, EpisodeJob]:
    ch6 = ch6_jobs(
        "c6",
        ConditionConfig(planner="random", stream="s", episodes=2),
        support=SupportParams("coverage", 0.5, 0.3, 2, 0.0),
        cp_max=0.3,
        model_path=Path("models/m/best.pt"),
        **SCENE,
    )
    ch4 = ch4_jobs(
        "c4",
        Ch4ConditionConfig(planner="oracle", stream="s", episodes=2),
        record_images=False,
        **SCENE,
    )
    ch5 = ch5_jobs(
        "c5",
        Ch5ConditionConfig(planner="replenish", stream="s", episodes=2),
        record_images=False,
        prob_threshold=0.5,
        scene_type="s",
        **SCENE,
    )
    ch3 = ch3_jobs(cfg=Ch3Config(), seed_of=lambda g: 100 + g, model=None)
    return {Ch6Job: ch6[1], Ch4Job: ch4[1], Ch5Job: ch5[1], Ch3Job: ch3[1]}


@pytest.mark.parametrize("kind", [Ch6Job, Ch4Job, Ch5Job, Ch3Job], ids=lambda k: k.__name__)
def test_a_job_of_each_chapter_pickles_and_round_trips(kind):
    job = _jobs()[kind]
    assert type(job) is kind and isinstance(job, EpisodeJob)
    assert isinstance(job, ShelfJob) == (kind is not Ch3Job)
    again = pickle.loads(pickle.dumps(job))
    assert type(again) is kind and again == job
    assert {f.name: getattr(again, f.name) for f in dataclasses.fields(again)} == {
        f.name: getattr(job, f.name) for f in dataclasses.fields(job)
    }
    assert job.index == 1 and type(job.index) is int and type(job.seed) is int


@pytest.mark.parametrize("kind", [Ch6Job, Ch4Job, Ch5Job, Ch3Job], ids=lambda k: k.__name__)
def test_a_misspelt_field_is_refused_at_construction(kind):
    job = _jobs()[kind]
    fields = {f.name: getattr(job, f.name) for f in dataclasses.fields(job)}
    assert kind(**fields) == job
    with pytest.raises(TypeError, match="record_image"):
        kind(**fields, record_image=True)  # record_images, misspelt
    with pytest.raises(TypeError, match="seeed"):
        dataclasses.replace(job, seeed=1)
    missing = dict(fields)
    del missing["seed"]
    with pytest.raises(TypeError, match="seed"):
        kind(**missing)
    with pytest.raises(dataclasses.FrozenInstanceError):
        job.seed = 1  # type: ignore[misc]


def test_a_job_copied_with_changes_keeps_its_type_and_the_rest():
    job = _jobs()[Ch6Job]
    other = dataclasses.replace(job, planner="oracle", record_images=True)
    assert type(other) is Ch6Job and (other.planner, other.record_images) == ("oracle", True)
    assert dataclasses.replace(other, planner=job.planner, record_images=job.record_images) == job
    assert repr(job) == "Ch6Job(condition='c6', stream='s', planner='random', index=1, seed=0)"
