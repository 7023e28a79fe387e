"""parallel's Ray backend: the processes backend's results in the same order, the
same bytes from real simulation jobs (scene shards, ch. 3 slide data, ch. 6 episodes), a
worker killed mid-run rerun by Ray with the same bytes out, a job that raises one line naming
it, an unreachable cluster one line before any job starts.

One local Ray instance of 2 CPUs serves the module (map_in_workers uses an instance this
process already holds as it is); the first two tests run before it starts."""

from __future__ import annotations

import dataclasses
import functools
import os
import signal
import time
from pathlib import Path

import pytest

from clutterbench.data.config import DatasetConfig, GenerateConfig
from clutterbench.data.generate import generate_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.parallel import ParallelConfig, connect_ray, map_in_workers
from clutterbench.sim.config import CameraConfig, SimConfig

ray = pytest.importorskip("ray", reason="the ray backend needs ray (make setup installs it)")

RAY = ParallelConfig(backend="ray")
JOBS = [{"condition": "c", "index": i, "seed": 7} for i in range(5)]


def _square(job: dict) -> tuple[int, int]:
    return job["index"], job["index"] ** 2


def _raises(job: dict) -> int:
    """Job 1 raises; jobs 2 on are still running when it does."""
    if job["index"] == 1:
        raise KeyError("box_6")
    if job["index"] >= 2:
        time.sleep(1.0)
    return job["index"]


def test_an_unreachable_cluster_is_one_line_before_any_job():
    start = time.perf_counter()
    with pytest.raises(ClutterbenchError) as err:
        map_in_workers("trials", _raises, JOBS, 2, ParallelConfig("ray", "ray://127.0.0.1:1"))
    message = str(err.value)
    assert "\n" not in message and not ray.is_initialized()
    assert message.startswith("parallel.address: the Ray cluster at ray://127.0.0.1:1 is ")
    assert time.perf_counter() - start < 10


def test_a_local_instance_of_workers_cpus_is_started_and_shut_down():
    assert not ray.is_initialized()
    assert map_in_workers("t", _square, JOBS, 1, RAY) == [(i, i * i) for i in range(5)]
    assert not ray.is_initialized()


@pytest.fixture(scope="module")
def local_ray():
    """One local instance for the module, as the backend starts one (connect_ray)."""
    assert connect_ray(ParallelConfig(backend="ray"), 2)
    yield
    ray.shutdown()


@pytest.mark.parametrize("workers", [1, 2])
def test_results_come_back_as_the_processes_backend_gives_them(workers, local_ray):
    expected = map_in_workers("t", _square, JOBS, workers)
    assert map_in_workers("t", _square, JOBS, workers, RAY) == expected
    assert ray.is_initialized()  # an instance it did not start is left running


def test_a_raising_job_is_the_same_one_line(local_ray, monkeypatch):
    monkeypatch.delenv("CLUTTERBENCH_TRACEBACK", raising=False)
    cancelled = []  # a cancel that races a finishing task aborts the driver inside Ray
    monkeypatch.setattr(ray, "cancel", lambda *args, **kwargs: cancelled.append(args))
    messages = []
    for parallel in (None, RAY):
        with pytest.raises(ClutterbenchError) as err:
            map_in_workers("trials", _raises, JOBS, 2, parallel)
        messages.append(str(err.value))
    assert messages[0] == messages[1] == "trials: condition c, index 1, seed 7: KeyError: 'box_6'"
    assert not cancelled, "the other jobs on an instance this run did not start were cancelled"


def _shards(out: Path, parallel: ParallelConfig | None) -> dict[str, bytes]:
    ds = DatasetConfig(n_scenes=2, families={"random": 1.0}, catalogue="various", n_objects=(2, 3))
    gen = GenerateConfig(shard_size=1, workers=2, max_attempts=30, datasets={"g": ds})
    sim = SimConfig(camera=CameraConfig(image_size=64))
    generate_dataset("g", ds, gen, sim, 0, out, parallel=parallel)
    return {p.name: p.read_bytes() for p in sorted(out.iterdir())}


def test_scene_shards_are_byte_identical_on_either_backend(local_ray, tmp_path):
    processes = _shards(tmp_path / "processes", None)
    assert sorted(processes) == ["manifest.json", "shard-00000.npz", "shard-00001.npz"]
    assert _shards(tmp_path / "ray", RAY) == processes


def _slides(out: Path, parallel: ParallelConfig | None) -> dict[str, bytes]:
    """The slides stage's data (ch. 3) at the tiny profile, 2 piles, on one backend."""
    import dataclasses

    from clutterbench.config import load_params, load_section
    from clutterbench.data.slide_crops import ScanConfig
    from clutterbench.data.slides import SlideDataConfig, generate_slide_dataset
    from clutterbench.sim.pile_config import PileCameraConfig, PileConfig, SlideConfig

    params = load_params(Path(__file__).parents[2] / "params.yaml")
    params["base"]["scale"] = "tiny"

    def section(cls, name):
        return load_section(cls, f"yamakuzushi.{name}", params)

    data = dataclasses.replace(section(SlideDataConfig, "data"), n_piles=2, workers=2)
    args = [section(c, n) for c, n in ((PileConfig, "pile"), (SlideConfig, "slide"))]
    args += [section(PileCameraConfig, "camera"), section(ScanConfig, "scan")]
    generate_slide_dataset(data, *args, 0, out, parallel)
    return {p.name: p.read_bytes() for p in sorted(out.iterdir())}


def test_slide_data_is_byte_identical_on_either_backend(local_ray, tmp_path):
    processes = _slides(tmp_path / "processes", None)
    assert "samples.npz" in processes
    assert _slides(tmp_path / "ray", RAY) == processes


@pytest.fixture(scope="module")
def episodes(tmp_path_factory):
    """Two ch. 6 pull_target episodes (an untrained network on a toy stream) and their
    records + MCAP bytes from the processes backend, in this process."""
    import torch

    from clutterbench.models import build_model
    from clutterbench.models.checkpoint import save_checkpoint
    from clutterbench.models.collapse_map import CollapseMapConfig
    from clutterbench.models.vgg import VGGConfig
    from clutterbench.trials.config import SceneStreamConfig
    from tests.toy_jobs import toy_ch6_jobs

    torch.manual_seed(0)
    net = CollapseMapConfig(
        input_size=64, encoder=VGGConfig(width=0.125), decoder_channels=(32, 16, 16, 8, 8)
    )
    cp = tmp_path_factory.mktemp("cp") / "best.pt"
    save_checkpoint(cp, "collapse_map", build_model("collapse_map", net), {"epoch": 0})
    stream = SceneStreamConfig(families={"stacked": 1, "random": 1}, n_objects=(3, 5))
    jobs = toy_ch6_jobs(
        "pull_target", stream, CameraConfig(image_size=64), episodes=2, model_path=cp
    )
    jobs = [dataclasses.replace(j, ch4_model_path=cp) for j in jobs]
    return jobs, _written(tmp_path_factory.mktemp("processes"), jobs, None)


def _written(out: Path, jobs: list, parallel: ParallelConfig | None, fn=None) -> dict:
    from clutterbench.trials.ch6.episodes import run_ch6_episode
    from clutterbench.trials.core.harness import run_episodes, write_mcap
    from clutterbench.trials.core.records import write_records

    results = run_episodes("t", fn or run_ch6_episode, jobs, 2, parallel)
    write_records(out / "records.jsonl", [r.record for r in results])
    write_mcap(out / "episodes.mcap", results, {"condition": "c"})
    return {f: (out / f).read_bytes() for f in ("records.jsonl", "episodes.mcap")}


def test_episodes_are_byte_identical_on_either_backend(local_ray, episodes, tmp_path):
    jobs, processes = episodes
    assert _written(tmp_path, jobs, RAY) == processes


def _killed_once(job, markers: str):
    """Episode 1's worker process dies (SIGKILL) the first time it runs it (a file in
    `markers` says it has)."""
    from clutterbench.trials.ch6.episodes import run_ch6_episode

    marker = Path(markers) / str(job.index)
    if job.index == 1 and not marker.exists():
        marker.touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return run_ch6_episode(job)


def test_a_killed_worker_is_rerun_and_the_bytes_are_the_same(local_ray, episodes, tmp_path):
    jobs, processes = episodes
    killed_once = functools.partial(_killed_once, markers=str(tmp_path))
    out = tmp_path / "out"
    assert _written(out, jobs, ParallelConfig("ray", max_retries=1), killed_once) == processes
    assert (tmp_path / "1").exists()  # it was killed once


def _always_killed(job: dict) -> int:
    os.kill(os.getpid(), signal.SIGKILL)
    return 0


def test_a_job_whose_worker_always_dies_is_one_line(local_ray):
    with pytest.raises(ClutterbenchError) as err:
        map_in_workers("trials", _always_killed, JOBS[:1], 1, ParallelConfig("ray", max_retries=1))
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("trials: condition c, index 0, seed 7: WorkerCrashedError")
