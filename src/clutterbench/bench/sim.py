"""`make bench`, simulation part: throughput -> reports/bench/sim.{json,md}, replay.json.

Measures in one process (one core): labelled scenes per second (place + settle + render +
every removal), render time per picture, and the raw SAPIEN cost of the same work (the
wall time inside SAPIEN's step and render calls of the very same run) so that the pipeline's
overhead is a ratio.
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from clutterbench.bench import header, measure_table, write_result
from clutterbench.config import load_params, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.data.generate import label_scene
from clutterbench.io import load_npz
from clutterbench.platform_info import cpu_description
from clutterbench.progress import progress_bar
from clutterbench.sim.config import SimConfig
from clutterbench.sim.labelling import act_on_spec, build_world, pull_outcomes, removal_matrix
from clutterbench.sim.render import render_depth_instance
from clutterbench.sim.renderer import add_depth_camera, ensure_renderer
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import TrialsConfig

BENCH_DATASET = "ch6"  # 5-10 boxes, shelved : stacked : random = 1 : 1 : 3
N_SCENES = 60
MAX_ATTEMPTS = 30


def bench_sim(n_scenes: int = N_SCENES, out_dir: Path = Path("reports/bench")) -> dict:
    params = load_params("params.yaml")
    params = {**params, "base": {**params["base"], "scale": "default"}}
    sim = load_section(SimConfig, "sim", params)
    ds = load_section(GenerateConfig, "generate", params).datasets[BENCH_DATASET]
    ensure_renderer()
    # Warm-up: the first picture of a process sets the renderer up, paid once per worker.
    warm = label_scene("warmup", ds, sim, 99, 0, MAX_ATTEMPTS)
    scenes, t0 = [], time.perf_counter()
    with progress_bar("bench: labelled scenes", total=n_scenes) as advance:
        for i in range(n_scenes):
            scenes.append(label_scene("bench", ds, sim, 0, i, MAX_ATTEMPTS))
            advance(1)
    pipeline_s = time.perf_counter() - t0
    steps = [s.steps for s in scenes]

    # Raw cost, measured in the same run: wall time inside SAPIEN's own step and render
    # calls; the rest is the pipeline's overhead (placement, rest checks, state restore).
    sapien_s = sum(s.sapien_s for s in scenes)

    ch6 = load_section(TrialsConfig, "trials", params).ch6
    removals_s, pulls_s = _label_costs(scenes, sim, ch6, n_scenes)
    render_s, raw_picture_s = _render_costs(warm, sim, n_scenes)
    first_s = {shader: first_picture_s(shader, sim) for shader in ("depth", "default")}

    result = {
        "dataset": BENCH_DATASET,
        "image_size": sim.camera.image_size,
        "scenes": n_scenes,
        "objects_mean": float(np.mean([s.spec.n for s in scenes])),
        "rejected_attempts": int(sum(sum(s.rejected.values()) for s in scenes)),
        "physics_steps_per_scene": float(np.mean(steps)),
        "labelled_scenes_per_s_per_core": n_scenes / pipeline_s,
        "ms_per_labelled_scene": 1e3 * pipeline_s / n_scenes,
        "render_ms_per_picture": 1e3 * render_s,
        "raw_render_ms_per_picture": 1e3 * raw_picture_s,
        "first_picture_s": first_s["depth"],
        "first_picture_default_shader_s": first_s["default"],
        "sapien_step_render_ms_per_scene": 1e3 * sapien_s / n_scenes,
        "overhead_ratio": pipeline_s / sapien_s,
        "ms_per_scene_deletion_labels": 1e3 * removals_s,
        "ms_per_scene_pull_outcome_labels": 1e3 * pulls_s,
        "pull_outcome_labels_vs_scene": pulls_s / (pipeline_s / n_scenes),
        "processes": 1,
        **cpu_description(),  # cpu_model, logical_cpus, torch_threads, machine
    }
    lines = header("Simulation benchmark (one core)", result) + measure_table(result)
    lines += [
        "",
        "Targets: >= 20 labelled scenes / s / core; overhead_ratio <= 2 "
        "(pipeline time / time inside SAPIEN step + render calls in the same run).",
        "first_picture_s: a fresh process's first picture, renderer made, with the depth "
        "cameras' shader (sim/renderer.py); first_picture_default_shader_s: the same with "
        "SAPIEN's default shader, whose image-based lighting the depth shader leaves out.",
        "Pull-outcome labels (generate.datasets.<name>.pull_outcomes): the trials' "
        "whole pull of every box of the same scenes, per scene, against the deletion labels "
        "(removal of every box) each labelled scene already includes; "
        "pull_outcome_labels_vs_scene is what they add to a labelled scene's time.",
    ]
    write_result(out_dir, "sim", result, lines)
    return result


def first_picture_s(shader: str, sim: SimConfig) -> float:
    """Seconds a fresh process (spawned) takes to build an empty shelf's world, make the
    renderer and render its first picture at the sim's image size, with the depth cameras'
    shader ("depth") or SAPIEN's default one ("default")."""
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=ctx) as pool:
        return pool.submit(_first_picture, shader, sim).result()


def _first_picture(shader: str, sim: SimConfig) -> float:
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.shelf import Shelf

    t0 = time.perf_counter()
    ensure_renderer()
    world = BoxWorld(Shelf(), sim.physics, render=True)
    cam = sim.camera
    if shader == "depth":
        camera = add_depth_camera(
            world.scene, "first", cam.image_size, np.deg2rad(cam.fovy_deg), cam.near_m, cam.far_m
        )
    else:
        camera = world.scene.add_camera(
            "first",
            cam.image_size,
            cam.image_size,
            np.deg2rad(cam.fovy_deg),
            cam.near_m,
            cam.far_m,
        )
    world.scene.update_render()
    camera.take_picture()
    camera.get_picture("Position")
    return time.perf_counter() - t0


def _label_costs(scenes: list, sim: SimConfig, ch6, n_scenes: int) -> tuple[float, float]:
    """Seconds per scene of the deletion labels (every box removed) and of the
    pull-consequence labels (the trials' whole pull of every box), on the same scenes."""
    pull = (ch6.pull_increment_m, ch6.grasp_lift_m)
    t0 = time.perf_counter()
    for sc in scenes:
        removal_matrix(sc.spec, sim.physics)
    removals_s = (time.perf_counter() - t0) / n_scenes
    t0 = time.perf_counter()
    for sc in scenes:
        pull_outcomes(sc.spec, sim.physics, pull)
    pulls_s = (time.perf_counter() - t0) / n_scenes
    return removals_s, pulls_s


def _render_costs(warm, sim: SimConfig, n_scenes: int) -> tuple[float, float]:
    """Seconds per picture of the pipeline's own render function and of SAPIEN's raw
    take_picture, each over n_scenes pictures of the warm-up scene after one untimed."""
    world = build_world(warm.spec, sim.physics, render=True)
    render_depth_instance(world, sim.camera)
    t0 = time.perf_counter()
    for _ in range(n_scenes):
        render_depth_instance(world, sim.camera)
    render_s = (time.perf_counter() - t0) / n_scenes
    cam = add_depth_camera(
        world.scene,
        "raw",
        sim.camera.image_size,
        np.deg2rad(sim.camera.fovy_deg),
        sim.camera.near_m,
        sim.camera.far_m,
    )
    world.scene.update_render()
    cam.take_picture()
    t0 = time.perf_counter()
    for _ in range(n_scenes):
        world.scene.update_render()
        cam.take_picture()
        cam.get_picture("Position")
    raw_picture_s = (time.perf_counter() - t0) / n_scenes
    return render_s, raw_picture_s


def bench_replay(
    scenes_per_dataset: int = 20,
    gen_dir: Path = Path("data/generate"),
    out_dir: Path = Path("reports/bench"),
) -> dict:
    """Replay stored labels from their specs (the CLI's code path) and count exact matches:
    removal rows, and for pull datasets a few (extract, support) pulls per scene. Needs the
    generated data; datasets not generated yet are skipped."""
    physics = load_section(SimConfig, "sim", load_params("params.yaml")).physics
    result: dict = {}
    for manifest_path in sorted(gen_dir.glob("*/manifest.json")):
        name = manifest_path.parent.name
        z = load_npz(gen_dir / name / "shard-00000.npz")
        rows = same = 0
        for k in range(min(scenes_per_dataset, len(z["scene_index"]))):
            spec = SceneSpec.from_json(str(z["spec_json"][k]))
            n = spec.n
            for x in range(n):
                got = act_on_spec(spec, physics, "remove", x)
                rows += 1
                same += int(np.array_equal(got, z["removal_m"][k, x, :n], equal_nan=True))
            if "pull_m" in z:
                n_max = z["pull_m"].shape[1]
                for x, sup in [(0, None), (1, 0), (n - 1, 1)]:
                    got = act_on_spec(spec, physics, "pull", x, sup)
                    if sup is not None:
                        got[sup] = np.nan
                    want = z["pull_m"][k, x, n_max if sup is None else sup, :n]
                    rows += 1
                    same += int(np.array_equal(got, want, equal_nan=True))
        result[name] = {"labels_replayed": rows, "bit_identical": same, "agreement": same / rows}
        print(f"replay {name}: {same}/{rows} labels bit-identical")
    result["machine"] = cpu_description()
    write_result(out_dir, "replay", result)
    return result
