"""The samples of the sim_profile part (bench/sim_profile.py): per simulation stage, the
first few units of each kind of its work, built by the stage's own job constructors from
params.yaml at default scale and the stage's own seed (base.seed: the stage's own first scenes,
episodes and games, read from the benchmark scenes where the stage reads them), and run by
its own job functions.

A stage's sample is grouped as its work is: generate by dataset, the trials stages by
planner (and perception), the games by variant, noise into robust-oracle episodes and
replays, testset and support into their phases. Each group knows its units at default scale,
so that the part can extrapolate the whole stage. The networks are not trained on this
machine: a stage whose planners read one gets a randomly initialised network of the default
config (models/<name>/best.pt in the sample's own project directory), which costs what the
trained one costs per forward pass but decides differently (episodes may be longer or
shorter). Upstream data a stage needs and that no stage here has made (support's val
scenes) is made first, with the repo's own functions, outside the profile.
"""

from __future__ import annotations

import dataclasses
import functools
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from clutterbench.bench.sim_profile_attribution import each
from clutterbench.bench.sim_profile_setup import Context, Group, Sample, by_key, plural

GENERATE_SCENES = {"ch4_same": 4, "ch4_various": 4, "ch4_same_test": 4, "ch4_various_test": 4}
"""Scenes sampled per generate dataset (their pairs' pulls make ch. 4 scenes slow); others
GENERATE_OTHERS."""
GENERATE_OTHERS = 16
EPISODES = {"trials": 1, "trials_ch4": 4, "trials_ch5": 4, "trials_arm": 3, "trials_ch3": 4}
"""Episodes (games) sampled per condition (variant)."""
NOISE_EPISODES = 3
NOISE_REPLAYED = ("random", "multi_step", "oracle", "physics_from_depth")
"""The trials conditions whose committed records the noise sample replays."""
TESTSET_STARTS = 3
"""Benchmark starts per ch. 6 stream in the testset sample."""
SUPPORT_SCENES = (6, 8)
"""(val, test) scenes of the support sample: the stage's 150 : 200."""
SLIDE_PILES = 6


# --- the stages -------------------------------------------------------------------------------


def generate(ctx: Context) -> Sample:
    """generate@<dataset>, every dataset: its first scenes as one shard (data.generate)."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import config_hash, shard_arrays, shard_path

    gen = ctx.section(GenerateConfig, "generate")
    pull = (ctx.trials.ch6.pull_increment_m, ctx.trials.ch6.grasp_lift_m)
    groups = []
    for name, ds in gen.datasets.items():
        k = GENERATE_SCENES.get(name, GENERATE_OTHERS)
        job = {
            "shard": 0,
            "indices": list(range(k)),
            "path": shard_path(Path("data/generate") / name, 0),
            "ds": ds,
            "sim": ctx.sim,
            "seed": ctx.base.seed,
            "dataset": name,
            "digest": config_hash(name, ds, ctx.sim, ctx.base.seed, pull),
            "max_attempts": gen.max_attempts,
            "pull": pull,
        }
        run = functools.partial(each, shard_arrays, [job])
        groups.append(Group(f"generate@{name}", "scene", k, ds.n_scenes, run))
    return Sample(groups, ["rendering is generate's (depth + instance of each scene)"])


def trials(ctx: Context) -> Sample:
    """trials (ch. 6, Table 6.3): every condition's first episodes, grouped by planner."""
    from clutterbench.trials.ch6.episodes import condition_jobs, load_planners, run_ch6_episode

    cfg = ctx.trials
    ctx.untrained(cfg.ch6.model, cfg.ch6.ch4_model, "box_head")
    load_planners(cfg.planner_modules, [c.planner for c in cfg.conditions.values()])
    n = EPISODES["trials"]

    def jobs_of(name: str, cond: Any) -> list[Any]:
        one = dataclasses.replace(cond, episodes=n)
        thresholds = Path("reports/support/thresholds.json")
        return condition_jobs(
            name, one, trials=cfg, sim=ctx.sim, seed=ctx.base.seed, thresholds=thresholds
        )[0]

    run = cfg.run_conditions  # as the stage runs them: the opt-in ones only when switched on
    groups = by_key(run, lambda c: c.planner, jobs_of, run_ch6_episode)
    notes = [
        f"the first {plural(n, 'episode')} of each of the {len(run)} conditions the stage "
        "runs, grouped by planner; networks randomly initialised (default config)",
        "not sampled: the stage's box-estimation figure (4 scenes, once)",
    ]
    return Sample(groups, notes)


def noise(ctx: Context) -> Sample:
    """noise: the robust oracles' first episodes, and replays of committed trials records."""
    from clutterbench.config import PACKAGE_REPO
    from clutterbench.trials.core.records import read_records
    from clutterbench.trials.noise.config import NoiseConfig
    from clutterbench.trials.noise.robust import robust_episode, run_robust_episode
    from clutterbench.trials.noise.run import ReplayJob, conditions_of, episode_jobs, replay_job

    cfg = ctx.section(NoiseConfig, "noise")
    names = conditions_of(cfg, ctx.trials)
    seed, k = ctx.base.seed, NOISE_EPISODES
    robust = [
        robust_episode(j, name, cfg)
        for name, base in cfg.robust.items()
        for j in episode_jobs(base, ctx.trials, ctx.sim, seed, k)
    ]
    replays = []
    for name in NOISE_REPLAYED:
        records = read_records(PACKAGE_REPO / "reports" / "trials" / name / "records.jsonl")[:k]
        for rec, ep in zip(records, episode_jobs(name, ctx.trials, ctx.sim, seed, k), strict=True):
            replays.append(
                ReplayJob(condition=name, index=ep.index, record=rec, episode=ep, noise=cfg)
            )
    full_robust = len(cfg.robust) * cfg.episodes
    full_replays = sum(min(cfg.episodes, ctx.trials.conditions[n].episodes) for n in names)
    full_replays += full_robust
    groups = [
        Group(
            "robust oracles",
            "episode",
            len(robust),
            full_robust,
            functools.partial(each, run_robust_episode, robust),
            ", ".join(cfg.robust),
        ),
        Group(
            f"replays ({cfg.draws} draws each)",
            "replayed episode",
            len(replays),
            full_replays,
            functools.partial(each, replay_job, replays),
            ", ".join(NOISE_REPLAYED),
        ),
    ]
    notes = [
        f"the first {k} episodes of each robust oracle, and replays of the first {k} committed "
        "reports/trials records of a few conditions (the stage replays every condition's and "
        "the robust oracles' own)"
    ]
    return Sample(groups, notes)


def testset(ctx: Context) -> Sample:
    """testset: benchmark starts labelled, the test set's deletions replayed and written,
    the leaderboard's baselines scored (the stage's own functions, in order)."""
    from clutterbench.criteria import label_thresholds
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.testset import export_testset, labelled_arrays
    from clutterbench.data.testset_load import load
    from clutterbench.support.baselines import baselines
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.support.scorecard import score
    from clutterbench.support.testset_starts import benchmark_start

    cfg = ctx.section(SupportEvalConfig, "support")
    ctx.untrained(cfg.model, "box_head")
    trials, sim, seed = ctx.trials, ctx.sim, ctx.base.seed
    streams: dict[str, int] = {}
    for cond in trials.conditions.values():
        streams[cond.stream] = max(streams.get(cond.stream, 0), cond.episodes)
    n_data = ctx.section(GenerateConfig, "generate").datasets[cfg.box_head.test_dataset].n_scenes
    k, n_starts = TESTSET_STARTS * len(streams), sum(streams.values())
    drop_m, tilt_deg = label_thresholds(ctx.params)
    thresholds = {"moved_m": cfg.moved_threshold_m, "drop_m": drop_m, "tilt_deg": tilt_deg}
    state: dict[str, Any] = {}

    def starts() -> None:  # support.testset_starts.benchmark_starts, on fewer episodes
        state["starts"] = []
        for s in streams:
            for i in range(TESTSET_STARTS):
                scene, target = benchmark_start(s, trials.streams[s], trials, sim, seed, i)
                state["starts"].append((scene, f"benchmark:{s}", i, target))

    def export() -> None:
        parts = [labelled_arrays(state["starts"])]
        export_testset(
            parts, sim.camera, thresholds, cfg.min_pixels, Path("data/testset"), sim.physics
        )
        state["ts"] = load(Path("data/testset"))

    def scored() -> None:
        ts, physics = state["ts"], (trials.ch6, cfg.test.catalogue, cfg.min_pixels)
        rows = baselines(
            ts, Path(f"models/{cfg.model}/best.pt"), Path("models/box_head/best.pt"), sim, physics
        )
        for name, (make, about) in rows.items():
            score(ts, make(), name, about)

    groups = [
        Group("benchmark starts labelled", "start", k, n_starts, starts),
        Group("deletions replayed, set written", "scene", k, n_starts + n_data, export),
        Group("baselines scored", "scene", k, n_starts + n_data, scored, phase=True),
    ]
    notes = [
        f"{TESTSET_STARTS} starts of each of {len(streams)} streams; the stage's "
        f"{cfg.box_head.test_dataset} scenes (generate's) are not read: their deletions and "
        "scores are extrapolated at the starts' cost per scene",
        "networks (collapse predictor, box head) randomly initialised",
    ]
    return Sample(groups, notes)


def support(ctx: Context) -> Sample:
    """support (Table 6.2): run_support, the stage's whole work, on a few val and test scenes
    (its val scenes, generate@ch6's, made first outside the profile)."""
    from clutterbench.parallel import ParallelConfig
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.support.run import SupportPaths, run_support

    cfg = ctx.section(SupportEvalConfig, "support")
    ctx.untrained(cfg.model, "box_head")
    n_val, n_test = SUPPORT_SCENES
    with ctx.unprofiled():
        _val_scenes(ctx, cfg.val_dataset, n_val)
        shutil.rmtree("support_out", ignore_errors=True)  # an earlier attempt's test scenes
    paths = SupportPaths.of(cfg, Path("support_out"), Path("support_out/scenes"))
    small = dataclasses.replace(cfg, val_scenes=n_val, test_scenes=n_test, workers=1)
    par = ParallelConfig()

    def run() -> None:
        run_support(ctx.params, ctx.base.seed, small, ctx.sim, par, paths, ctx.trials.ch6)

    full = cfg.val_scenes + cfg.test_scenes
    group = Group("val + test scenes", "scene", n_val + n_test, full, run, "run_support")
    notes = [
        f"{n_val} val scenes ({cfg.val_dataset}, made here by generate's own functions outside "
        f"the profile, all in the val split) and {n_test} test scenes (generated by the stage) "
        f"in the stage's {cfg.val_scenes} : {cfg.test_scenes}; networks randomly initialised",
    ]
    return Sample([group], notes)


def _val_scenes(ctx: Context, dataset: str, n: int) -> None:
    """The first `n` scenes of generate@<dataset> (data/generate) and a split putting them all
    in val (data/split): the support stage's input."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import generate_dataset
    from clutterbench.io import write_json
    from clutterbench.parallel import ParallelConfig

    gen = ctx.section(GenerateConfig, "generate")
    ds = dataclasses.replace(gen.datasets[dataset], n_scenes=n)
    pull = (ctx.trials.ch6.pull_increment_m, ctx.trials.ch6.grasp_lift_m)
    out = Path("data/generate") / dataset
    one = dataclasses.replace(gen, workers=1)
    manifest = generate_dataset(
        dataset, ds, one, ctx.sim, ctx.base.seed, out, pull, ParallelConfig()
    )
    split = {
        "dataset": dataset,
        "config_hash": manifest["config_hash"],
        "train": [],
        "val": list(range(n)),
        "test": [],
    }
    write_json(Path("data/split") / f"{dataset}.json", split)


def slides(ctx: Context) -> Sample:
    """slides (ch. 3 ConvNet data): the first piles, each with its slides simulated."""
    from clutterbench.data.slide_crops import ScanConfig
    from clutterbench.data.slides import SlideDataConfig, label_pile, pile_seed
    from clutterbench.sim.pile_config import PileCameraConfig, PileConfig, SlideConfig

    data = ctx.section(SlideDataConfig, "yamakuzushi.data")
    fixed = {
        "pile": ctx.section(PileConfig, "yamakuzushi.pile"),
        "slide": ctx.section(SlideConfig, "yamakuzushi.slide"),
        "camera": ctx.section(PileCameraConfig, "yamakuzushi.camera"),
        "scan": ctx.section(ScanConfig, "yamakuzushi.scan"),
        "slides_per_pile": data.slides_per_pile,
    }
    jobs = [
        {"index": i, "seed": pile_seed(ctx.base.seed, "ch3_data", i)} | fixed
        for i in range(SLIDE_PILES)
    ]
    run = functools.partial(each, label_pile, jobs)
    group = Group("piles labelled", "pile", SLIDE_PILES, data.n_piles, run, "label_pile")
    notes = ["not sampled: the balancing and split of the samples (once)"]
    return Sample([group], notes)


def trials_ch3(ctx: Context) -> Sample:
    """trials_ch3 (Fig. 3.15): the first games of every variant."""
    from clutterbench.criteria import CollapseFreeConfig
    from clutterbench.data.slides import pile_seed
    from clutterbench.trials.ch3.config import Ch3Config
    from clutterbench.trials.ch3.games import ch3_jobs, run_ch3_game

    cfg = ctx.section(Ch3Config, "yamakuzushi")
    ctx.untrained("slide_convnet")
    collapse_free = ctx.section(CollapseFreeConfig, "trials.collapse_free")
    k, seed = EPISODES["trials_ch3"], ctx.base.seed
    groups = []
    for v in cfg.games.variants:
        one = dataclasses.replace(
            cfg, games=dataclasses.replace(cfg.games, variants=(v,), n_games=k)
        )
        jobs = ch3_jobs(
            cfg=one,
            seed_of=lambda g: pile_seed(seed, "ch3_games", g),
            model="models/slide_convnet/best.pt",
            collapse_free=collapse_free,
        )
        run = functools.partial(each, run_ch3_game, jobs)
        groups.append(Group(v, "game", len(jobs), cfg.games.n_games, run, f"variant {v}"))
    notes = [f"{plural(k, 'game')} of each variant; the slide ConvNet randomly initialised"]
    return Sample(groups, notes)


def trials_ch4(ctx: Context) -> Sample:
    """trials_ch4 (Table 4.1): every condition's first trials, grouped by planner and
    perception."""
    from clutterbench.trials.ch4.episodes import ch4_jobs, run_ch4_episode

    cfg = ctx.trials
    ctx.untrained(*sorted({c.model for c in cfg.ch4_conditions.values() if c.model}))
    k = EPISODES["trials_ch4"]

    def jobs_of(name: str, cond: Any) -> list[Any]:
        return ch4_jobs(
            name, dataclasses.replace(cond, episodes=k), trials=cfg, sim=ctx.sim, seed=ctx.base.seed
        )

    def key(c: Any) -> str:
        return f"{c.planner} ({c.perception})" if c.model else c.planner

    groups = by_key(dict(cfg.ch4_conditions), key, jobs_of, run_ch4_episode)
    return Sample(
        groups,
        [
            f"{plural(k, 'trial')} of each condition; ch. 4 networks randomly initialised",
            "not sampled: the stage's Fig. 4.8 (once)",
        ],
    )


def trials_ch5(ctx: Context) -> Sample:
    """trials_ch5 (Table 5.2): every condition's first trials, grouped by planner and
    perception."""
    from clutterbench.trials.ch5.episodes import (
        ch5_jobs,
        check_models,
        collapse_threshold,
        run_ch5_episode,
    )

    cfg = ctx.trials
    ctx.untrained(cfg.ch5.model, "detector")
    check_models(dict(cfg.ch5_conditions), cfg.ch5)
    prob = collapse_threshold(cfg.ch5)
    detector = any(c.perception == "detector" for c in cfg.ch5_conditions.values())
    k = EPISODES["trials_ch5"]

    def jobs_of(name: str, cond: Any) -> list[Any]:
        one = dataclasses.replace(cond, episodes=k)
        scene_type = cond.stream.removeprefix("ch5_")
        return ch5_jobs(
            name,
            one,
            trials=cfg,
            sim=ctx.sim,
            seed=ctx.base.seed,
            prob_threshold=prob,
            scene_type=scene_type,
            oracle_detector=detector,
        )

    groups = by_key(
        dict(cfg.ch5_conditions),
        lambda c: f"{c.planner} ({c.perception})",
        jobs_of,
        run_ch5_episode,
    )
    notes = [
        f"{plural(k, 'trial')} of each condition; the detector and the collapse map network "
        "randomly initialised (an untrained detector finds other clusters than a trained one)"
    ]
    return Sample(groups, notes)


def trials_arm(ctx: Context) -> Sample:
    """trials_arm: the first episode of every arm condition (Pandas in ManiSkill), built as
    stages/trials_arm.py builds them."""
    from clutterbench.trials.arm.episodes import run_arm_episode
    from clutterbench.trials.ch4.episodes import ch4_jobs
    from clutterbench.trials.ch6.episodes import condition_jobs, load_planners

    cfg = ctx.trials
    ctx.untrained(
        cfg.ch6.model,
        cfg.ch6.ch4_model,
        *sorted({c.model for c in cfg.ch4_conditions.values() if c.model}),
    )
    k = EPISODES["trials_arm"]
    groups = []
    for name, arm in cfg.arm_conditions.items():
        if arm.of in cfg.conditions:
            cond = dataclasses.replace(cfg.conditions[arm.of], executor="arm", episodes=k)
            load_planners(cfg.planner_modules, [cond.planner])
            jobs = condition_jobs(
                name,
                cond,
                trials=cfg,
                sim=ctx.sim,
                seed=ctx.base.seed,
                thresholds=Path("reports/support/thresholds.json"),
            )[0]
        else:
            cond = dataclasses.replace(cfg.ch4_conditions[arm.of], executor="arm", episodes=k)
            jobs = ch4_jobs(name, cond, trials=cfg, sim=ctx.sim, seed=ctx.base.seed, arm=cfg.arm)
        run = functools.partial(each, run_arm_episode, jobs)
        groups.append(
            Group(name, "episode", len(jobs), arm.episodes, run, f"{arm.of}, executor arm")
        )
    notes = [f"{plural(k, 'episode')} of each arm condition; networks randomly initialised"]
    return Sample(groups, notes)


STAGES: dict[str, Callable[[Context], Sample]] = {
    "generate": generate,
    "trials": trials,
    "noise": noise,
    "testset": testset,
    "support": support,
    "slides": slides,
    "trials_ch3": trials_ch3,
    "trials_ch4": trials_ch4,
    "trials_ch5": trials_ch5,
    "trials_arm": trials_arm,
}
