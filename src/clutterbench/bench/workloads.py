"""The ray bench's workloads (bench/scaling.py): each one a stage's own jobs, built by that
stage's own job constructors from params.yaml at the bench's scale, but on the bench's own
seed (SEED: no stage's scenes, piles or games) and, where a stage's planners read a trained
network, only its conditions that need none (the bench runs before, or without, any
training). Trials workloads take their `n` jobs round-robin over the conditions they run, in
params order, so each condition weighs as it does in the stage.

- generate: shards of the ch6 dataset's scenes (data.generate.shard_arrays).
- trials: ch. 6 episodes of every condition whose planner needs no network (mix_conditions).
- slides: one pile per job (data.slides.label_pile).
- trials_ch4: ch. 4 trials of the random and oracle conditions (CH4_NETWORK_FREE).
- trials_ch5: ch. 5 episodes of the conditions that read neither the collapse map network
  nor the detector (ch5_network_free: the oracles on the generator's clusters).
- trials_ch3: Yamakuzushi games of the variants without the ConvNet (CH3_NETWORK_FREE).
- trials_arm: arm-level episodes (Pandas, ManiSkill) of trials.arm_conditions. Every one of
  them repeats a network planner, so the workload runs those whose networks (and, for a ch.
  6 condition, the support stage's thresholds) exist, and is skipped when none does
  (`unavailable`).

The new workloads (trials_ch5, trials_ch3, trials_arm) record no MCAP images, as trials_ch4's.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from clutterbench.config import load_params, load_section
from clutterbench.errors import ClutterbenchError

if TYPE_CHECKING:
    from clutterbench.trials.ch3.games import Ch3Job
    from clutterbench.trials.ch4.episodes import Ch4Job
    from clutterbench.trials.ch5.episodes import Ch5Job
    from clutterbench.trials.ch6.episodes import Ch6Job

WORKLOADS = (
    "generate",
    "trials",
    "slides",
    "trials_ch4",
    "trials_ch5",
    "trials_ch3",
    "trials_arm",
)
SEED = 99  # the bench's own scenes, no stage's
ARM_THRESHOLDS = Path("reports/support/thresholds.json")
"""The support stage's thresholds, which the trials_arm stage's ch. 6 conditions read."""


def scale_params(scale: str) -> dict[str, Any]:
    params = load_params("params.yaml")
    return {**params, "base": {**params["base"], "scale": scale}}


J = TypeVar("J")


def mix_conditions(trials: Any) -> list[str]:
    """The trials stage's conditions whose planner needs no trained network (its declared
    networks: the bench runs before, or without, any training), in params order."""
    from clutterbench.trials.ch6.planners import planner_info

    return [k for k, c in trials.conditions.items() if not planner_info(c.planner).networks]


def job_conditions(jobs: list[Any]) -> list[str]:
    """The conditions (a game's variant) that `jobs` run, in order of first appearance (the
    data workloads' jobs, dicts, run none)."""
    names = [getattr(j, "condition", None) for j in jobs]
    return [n for n in dict.fromkeys(names) if n is not None]


def round_robin(by_condition: list[list[J]], n: int) -> list[J]:
    """The first `n` jobs taken one per condition in turn (each list as long as the first)."""
    return [js[i] for i in range(len(by_condition[0])) for js in by_condition][:n]


def workload_jobs(
    workload: str, scale: str, shards: int, shard_size: int, episodes: int
) -> tuple[Any, list[Any], int]:
    """(job function, jobs, units): units are scenes (generate), piles (slides), games
    (trials_ch3) or episodes (the other trials); `episodes` is the job count of every trials
    workload."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.config import TrialsConfig

    if workload not in WORKLOADS:
        raise ClutterbenchError(f"bench: no workload {workload!r} ({', '.join(WORKLOADS)})")
    params = scale_params(scale)
    sim = load_section(SimConfig, "sim", params)
    trials = load_section(TrialsConfig, "trials", params)
    if workload == "generate":
        return _generate_jobs(params, trials, sim, shards, shard_size)
    if workload == "slides":
        return _slide_jobs(params, shards)
    if workload == "trials_ch4":
        return _ch4_jobs(params, trials, sim, episodes)
    if workload == "trials_ch5":
        return _ch5_jobs(trials, sim, episodes)
    if workload == "trials_ch3":
        return _ch3_jobs(params, episodes)
    if workload == "trials_arm":
        return _arm_jobs(trials, sim, episodes)
    return _trials_jobs(trials, sim, episodes)


def unavailable(workload: str, scale: str) -> str | None:
    """Why `workload` cannot run here (no condition it may run: a network not trained, a
    package missing), or None: the bench skips it with that line instead of failing."""
    if workload == "trials_arm":
        import importlib.util

        if importlib.util.find_spec("mani_skill") is None:
            return "ManiSkill is not installed (make setup installs it)"
    try:
        workload_jobs(workload, scale, 1, 1, 1)
    except ClutterbenchError as exc:
        return str(exc)
    return None


def _generate_jobs(
    params: dict[str, Any], trials: Any, sim: Any, shards: int, shard_size: int
) -> tuple[Any, list[dict[str, Any]], int]:
    """The generate stage's shards of the ch6 dataset (data.generate.shard_arrays)."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import shard_arrays

    gen = load_section(GenerateConfig, "generate", params)
    pull = (trials.ch6.pull_increment_m, trials.ch6.grasp_lift_m)
    jobs = [
        {
            "shard": k,
            "indices": list(range(k * shard_size, (k + 1) * shard_size)),
            "ds": gen.datasets["ch6"],
            "sim": sim,
            "seed": SEED,
            "dataset": "bench",
            "digest": "bench",
            "max_attempts": gen.max_attempts,
            "pull": pull,
        }
        for k in range(shards)
    ]
    return shard_arrays, jobs, shards * shard_size


def _trials_jobs(trials: Any, sim: Any, episodes: int) -> tuple[Any, list[Ch6Job], int]:
    """The trials stage's mix: ch. 6 episodes of its network-free conditions, round-robin."""
    from clutterbench.planning.ch6.support import SupportParams
    from clutterbench.trials.ch6.episodes import ch6_jobs, run_ch6_episode
    from clutterbench.trials.config import ConditionConfig

    names = mix_conditions(trials)
    if not names:
        raise ClutterbenchError("bench trials: no ch. 6 condition without a network to run")
    support = SupportParams("coverage", 0.5, 0.3, 2, 0.0)  # the truth planners' graph rule
    per = -(-episodes // len(names))  # episodes per condition, enough for round_robin
    by_condition = []
    for name in names:
        cond = trials.conditions[name]
        cond = ConditionConfig(planner=cond.planner, stream=cond.stream, episodes=per)
        by_condition.append(
            ch6_jobs(
                f"bench_{name}",
                cond,
                trials=trials,
                sim=sim,
                seed=SEED,
                support=support,
                cp_max=0.5,
                model_path=Path("models/none/best.pt"),  # no planner of the mix loads a network
            )
        )
    jobs = round_robin(by_condition, episodes)
    return run_ch6_episode, jobs, episodes


def _slide_jobs(params: dict[str, Any], piles: int) -> tuple[Any, list[dict[str, Any]], int]:
    """The slides stage's jobs (data.slides.generate_slide_dataset): one pile each."""
    from clutterbench.data.slide_crops import ScanConfig
    from clutterbench.data.slides import SlideDataConfig, label_pile, pile_seed
    from clutterbench.sim.pile_config import PileCameraConfig, PileConfig, SlideConfig

    def section(cls, name):
        return load_section(cls, f"yamakuzushi.{name}", params)

    data = section(SlideDataConfig, "data")
    fixed = {
        "pile": section(PileConfig, "pile"),
        "slide": section(SlideConfig, "slide"),
        "camera": section(PileCameraConfig, "camera"),
        "scan": section(ScanConfig, "scan"),
        "slides_per_pile": data.slides_per_pile,
    }
    jobs = [{"index": i, "seed": pile_seed(SEED, "ch3_data", i)} | fixed for i in range(piles)]
    return label_pile, jobs, piles


CH4_NETWORK_FREE = ("random", "oracle")
"""The ch. 4 planners the bench's trials_ch4 workload runs (the risk planner reads a network)."""


def _ch4_jobs(
    params: dict[str, Any], trials: Any, sim: Any, episodes: int
) -> tuple[Any, list[Ch4Job], int]:
    """The trials_ch4 stage's network-free conditions, `episodes` trials round-robin."""
    from clutterbench.trials.ch4.episodes import run_ch4_episode

    names = [k for k, c in trials.ch4_conditions.items() if c.planner in CH4_NETWORK_FREE]
    if not names:
        raise ClutterbenchError("bench trials_ch4: no ch. 4 condition without a network to run")
    per = -(-episodes // len(names))  # episodes per condition, enough for round_robin
    by_condition = []
    for name in names:
        cond = trials.ch4_conditions[name]
        cond = dataclasses.replace(cond, episodes=per)
        by_condition.append(_bench_ch4_jobs(name, cond, trials, sim))
    jobs = round_robin(by_condition, episodes)
    return run_ch4_episode, jobs, episodes


def _bench_ch4_jobs(name: str, cond: Any, trials: Any, sim: Any) -> list[Ch4Job]:
    """Ch. 4 condition `cond`'s jobs on the bench's seed, without MCAP images, as the
    trials_ch4 (kinematic) and trials_arm (cond.executor "arm") stages build them."""
    from clutterbench.trials.ch4.episodes import ch4_jobs

    return ch4_jobs(
        f"bench_{name}",
        cond,
        trials=trials,
        sim=sim,
        seed=SEED,
        arm=trials.arm if cond.executor == "arm" else None,
        record_images=False,
    )


def ch5_network_free(cond: Any) -> bool:
    """A ch. 5 condition that reads no network: its planner predicts no collapse (no collapse
    map network) and it perceives the generator's clusters (no detector)."""
    from clutterbench.trials.ch5.episodes import COLLAPSE_PLANNERS

    return cond.planner not in COLLAPSE_PLANNERS and cond.perception != "detector"


def _ch5_jobs(trials: Any, sim: Any, episodes: int) -> tuple[Any, list[Ch5Job], int]:
    """The trials_ch5 stage's network-free conditions, `episodes` episodes round-robin. Its
    oracles do not also simulate the actions seen through the detector (the stage's do,
    `oracle_detector`, since its other conditions perceive with the detector): that needs the
    detector network."""
    from clutterbench.trials.ch5.episodes import ch5_jobs, run_ch5_episode

    names = [k for k, c in trials.ch5_conditions.items() if ch5_network_free(c)]
    if not names:
        raise ClutterbenchError("bench trials_ch5: no ch. 5 condition without a network to run")
    # no collapse map is read, so the threshold is never used: params' own, else the default
    prob = trials.ch5.prob_threshold if trials.ch5.prob_threshold is not None else 0.5
    per = -(-episodes // len(names))  # episodes per condition, enough for round_robin
    by_condition = []
    for name in names:
        cond = dataclasses.replace(trials.ch5_conditions[name], episodes=per)
        by_condition.append(
            ch5_jobs(
                f"bench_{name}",
                cond,
                trials=trials,
                sim=sim,
                seed=SEED,
                prob_threshold=prob,
                scene_type=cond.stream.removeprefix("ch5_"),
                oracle_detector=False,  # oracle_detector: no detector network
                record_images=False,
            )
        )
    jobs = round_robin(by_condition, episodes)
    return run_ch5_episode, jobs, episodes


CH3_NETWORK_FREE = ("no_convnet", "random", "oracle")
"""The Yamakuzushi variants the bench's trials_ch3 workload plays (convnet and
convnet_no_pomdp read the slide ConvNet)."""


def _ch3_jobs(params: dict[str, Any], games: int) -> tuple[Any, list[Ch3Job], int]:
    """The trials_ch3 stage's network-free variants, `games` games round-robin (game g of
    every variant on the pile of the bench's seed stream ch3_games, g)."""
    from clutterbench.criteria import CollapseFreeConfig
    from clutterbench.data.slides import pile_seed
    from clutterbench.trials.ch3.config import Ch3Config
    from clutterbench.trials.ch3.games import ch3_jobs, run_ch3_game

    cfg = load_section(Ch3Config, "yamakuzushi", params)
    collapse_free = load_section(CollapseFreeConfig, "trials.collapse_free", params)
    variants = [v for v in cfg.games.variants if v in CH3_NETWORK_FREE]
    if not variants:
        raise ClutterbenchError("bench trials_ch3: no Yamakuzushi variant without a network")
    per = -(-games // len(variants))  # games per variant, enough for round_robin
    by_variant = []
    for v in variants:
        one = dataclasses.replace(
            cfg, games=dataclasses.replace(cfg.games, variants=(v,), n_games=per, mcap_images=False)
        )
        by_variant.append(
            ch3_jobs(
                cfg=one,
                seed_of=lambda g: pile_seed(SEED, "ch3_games", g),
                model=None,
                collapse_free=collapse_free,
            )
        )
    jobs = round_robin(by_variant, games)
    return run_ch3_game, jobs, games


def _arm_condition_jobs(
    name: str, arm: Any, trials: Any, sim: Any, episodes: int
) -> list[Ch4Job] | list[Ch6Job]:
    """Arm condition `name`'s first `episodes` episodes on the bench's seed, built as the
    trials_arm stage builds them; a ClutterbenchError when its network (or a ch. 6
    condition's support thresholds) is missing."""
    from clutterbench.trials.ch6.episodes import condition_jobs, load_planners

    if arm.of in trials.conditions:
        cond = dataclasses.replace(trials.conditions[arm.of], executor="arm", episodes=episodes)
        load_planners(trials.planner_modules, [cond.planner])
        no_images = dataclasses.replace(trials, mcap_images=False)
        jobs, _, _ = condition_jobs(
            f"bench_{name}", cond, trials=no_images, sim=sim, seed=SEED, thresholds=ARM_THRESHOLDS
        )
        return jobs
    cond = dataclasses.replace(trials.ch4_conditions[arm.of], executor="arm", episodes=episodes)
    if cond.model is not None and not Path(f"models/{cond.model}/best.pt").exists():
        raise ClutterbenchError(f"models/{cond.model}/best.pt missing; run train@{cond.model}")
    return _bench_ch4_jobs(name, cond, trials, sim)


def arm_conditions(trials: Any, sim: Any) -> tuple[list[str], dict[str, str]]:
    """The arm conditions the bench can run here (their networks exist), in params order,
    and why each other one cannot."""
    ok, why = [], {}
    for name, arm in trials.arm_conditions.items():
        try:
            _arm_condition_jobs(name, arm, trials, sim, 1)
        except ClutterbenchError as exc:
            why[name] = str(exc)
        else:
            ok.append(name)
    return ok, why


def _arm_jobs(trials: Any, sim: Any, episodes: int) -> tuple[Any, list[Ch4Job | Ch6Job], int]:
    """The trials_arm stage's conditions whose networks exist, `episodes` episodes
    round-robin; none: a ClutterbenchError naming what is missing."""
    from clutterbench.trials.arm.episodes import run_arm_episode

    names, why = arm_conditions(trials, sim)
    if not names:
        missing = "; ".join(f"{k}: {v}" for k, v in why.items()) or "trials.arm_conditions empty"
        raise ClutterbenchError(f"bench trials_arm: no arm condition can run ({missing})")
    per = -(-episodes // len(names))  # episodes per condition, enough for round_robin
    by_condition = [
        _arm_condition_jobs(name, trials.arm_conditions[name], trials, sim, per) for name in names
    ]
    jobs = round_robin(by_condition, episodes)
    return run_arm_episode, jobs, episodes
