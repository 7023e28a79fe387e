"""Stage noise's work: the robust search oracles' episodes, then every replayed condition's
episodes in `noise.draws` perturbed worlds -> reports/noise/summary.json (per condition and
criterion: the table's rate, each draw's, their mean and spread, the share of the table's
successes that survive a draw), reports/noise/episodes.csv (one row per episode and draw),
reports/noise/robust/<condition>/ (the robust oracles' records, as the trials write them)."""

from __future__ import annotations

import csv
import dataclasses
import io
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json, write_text
from clutterbench.parallel import ParallelConfig, map_in_workers
from clutterbench.sim.config import SimConfig
from clutterbench.trials.ch6.episodes import ch6_jobs, job_spec
from clutterbench.trials.ch6.jobs import Ch6Job
from clutterbench.trials.ch6.planners import planner_info
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.harness import run_episodes, write_condition
from clutterbench.trials.core.records import read_records
from clutterbench.trials.noise.config import NoiseConfig
from clutterbench.trials.noise.draws import REPLAY, draw
from clutterbench.trials.noise.replay import replay_episode, survival
from clutterbench.trials.noise.robust import CRITERIA, robust_episode, run_robust_episode

TRIALS = Path("reports/trials")
OUT = Path("reports/noise")
DATA = Path("data/noise")


@dataclasses.dataclass(frozen=True, kw_only=True)
class ReplayJob:
    """One episode of one condition, replayed in each of its draws."""

    condition: str
    index: int
    record: dict[str, Any]
    episode: Ch6Job
    noise: NoiseConfig

    @property
    def stream(self) -> str:
        return self.episode.stream


def replay_job(job: ReplayJob) -> list[tuple[bool, bool]]:
    """(success, strict success) of the episode in each draw."""
    ep = job.episode
    spec = job_spec(ep)
    out = []
    for k in range(job.noise.draws):
        d = draw(job.noise, ep.seed, ep.stream, ep.index, k, spec.n, REPLAY)
        r = replay_episode(job.record, spec, d, ep.physics, ep.params.pull, ep.collapse_free)
        out.append((r.success, r.strict_success))
    return out


def conditions_of(cfg: NoiseConfig, trials: TrialsConfig) -> list[str]:
    """The replayed ch. 6 conditions (noise.conditions, else every one the trials ran whose
    planner saw exact depth and the simulator's masks: a sensed row's noise is its sensor),
    checked against trials."""
    seen_ideal = [
        name
        for name, c in trials.run_conditions.items()
        if (c.sensing, c.perception) == ("ideal", "instance")
    ]
    names = list(cfg.conditions) or seen_ideal
    for name in names:
        if name not in trials.conditions:
            raise ClutterbenchError(f"noise.conditions: '{name}' is no trials.conditions entry")
        if name in trials.opt_in.skipped:
            raise ClutterbenchError(
                f"noise.conditions: '{name}' is opt-in and not run (trials.opt_in.run: false)"
            )
        if trials.conditions[name].executor != "kinematic":
            raise ClutterbenchError(
                f"noise.conditions: '{name}' runs on the {trials.conditions[name].executor} "
                "executor; replays run on the kinematic one"
            )
    for name, base in cfg.robust.items():
        if base not in trials.conditions:
            raise ClutterbenchError(f"noise.robust.{name}: '{base}' is no trials.conditions entry")
        if planner_info(trials.conditions[base].planner).role != "oracle":
            raise ClutterbenchError(f"noise.robust.{name}: '{base}' is not a search oracle's")
        if name in trials.conditions:
            raise ClutterbenchError(f"noise.robust.{name}: the name is a trials condition")
    return names


def episode_jobs(
    name: str, trials: TrialsConfig, sim: SimConfig, seed: int, n: int
) -> list[Ch6Job]:
    """The first `n` episode jobs of trials condition `name`, as the trials built them (the
    planner's networks and thresholds are not needed to replay or to search)."""
    cond = trials.conditions[name]
    cond = dataclasses.replace(cond, episodes=min(n, cond.episodes))
    return ch6_jobs(
        name, cond, trials=trials, sim=sim, seed=seed, support=None, cp_max=1.0, model_path=None
    )


def run_robust(
    cfg: NoiseConfig, trials: TrialsConfig, sim: SimConfig, seed: int, parallel: ParallelConfig
) -> dict[str, list[dict[str, Any]]]:
    """The robust oracles' episodes -> their records per condition (also written)."""
    jobs = [
        robust_episode(j, name, cfg)
        for name, base in cfg.robust.items()
        for j in episode_jobs(base, trials, sim, seed, cfg.episodes)
    ]
    if not jobs:
        return {}
    results = run_episodes("noise: robust oracles", run_robust_episode, jobs, cfg.workers, parallel)
    records = {}
    for name, base in cfg.robust.items():
        about = {
            "condition": name,
            "planner": f"{trials.conditions[base].planner}_robust",
            "stream": trials.conditions[base].stream,
            "mirrors": base,
            "robust_draws": cfg.robust_draws,
        }
        write_condition(name, results, about, OUT / "robust", DATA)
        records[name] = [r.record for r in results if r.record["condition"] == name]
    return records


def run_noise(
    seed: int,
    cfg: NoiseConfig,
    trials: TrialsConfig,
    sim: SimConfig,
    parallel: ParallelConfig,
) -> dict[str, Any]:
    """The whole stage -> the summary (also written)."""
    names = conditions_of(cfg, trials)
    records = {}
    for name in names:
        path = TRIALS / name / "records.jsonl"
        if not path.exists():
            raise ClutterbenchError(f"{path} missing; run the trials stage")
        records[name] = read_records(path)[: cfg.episodes]
    robust = run_robust(cfg, trials, sim, seed, parallel)
    records |= robust
    jobs = []
    for name, recs in records.items():
        base = cfg.robust.get(name, name)
        eps = episode_jobs(base, trials, sim, seed, len(recs))
        for rec, ep in zip(recs, eps, strict=True):
            if rec["episode"] != ep.index:
                raise ClutterbenchError(f"{name}: record {rec['episode']} out of order")
            jobs.append(
                ReplayJob(condition=name, index=ep.index, record=rec, episode=ep, noise=cfg)
            )
    outcomes = map_in_workers("noise: replays", replay_job, jobs, cfg.workers, parallel)
    summary = summarise(records, jobs, outcomes, trials, cfg)
    write_json(OUT / "summary.json", summary)
    write_text(OUT / "episodes.csv", episodes_csv(jobs, outcomes))
    return summary


def summarise(
    records: Mapping[str, list[dict[str, Any]]],
    jobs: list[ReplayJob],
    outcomes: list[list[tuple[bool, bool]]],
    trials: TrialsConfig,
    cfg: NoiseConfig,
) -> dict[str, Any]:
    by: dict[str, list[list[tuple[bool, bool]]]] = {}
    for job, out in zip(jobs, outcomes, strict=True):
        by.setdefault(job.condition, []).append(out)
    conditions = {}
    for name, recs in records.items():
        base = cfg.robust.get(name, name)
        row: dict[str, Any] = {
            "planner": recs[0]["planner"] if recs else trials.conditions[base].planner,
            "stream": trials.conditions[base].stream,
            "robust_of": cfg.robust.get(name),
        }
        for c, key in enumerate(CRITERIA):
            nominal = [bool(r[key]) for r in recs]
            row[key] = survival(nominal, [[o[c] for o in e] for e in by.get(name, [])])
        conditions[name] = row
    return {"noise": dataclasses.asdict(cfg), "conditions": conditions}


def episodes_csv(jobs: list[ReplayJob], outcomes: list[list[tuple[bool, bool]]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        [
            "condition",
            "episode",
            "draw",
            "success_table",
            "success",
            "strict_success_table",
            "strict_success",
        ]
    )
    for job, out in zip(jobs, outcomes, strict=True):
        for k, (s, strict) in enumerate(out):
            w.writerow(
                [
                    job.condition,
                    job.index,
                    k,
                    int(job.record["success"]),
                    int(s),
                    int(job.record["strict_success"]),
                    int(strict),
                ]
            )
    return buf.getvalue()
