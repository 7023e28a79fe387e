"""`make bench`, sensor part: what the depth-sensor model costs per image -> reports/bench/
sensor.{json,md}.

The first observations of bench scenes of the 3-10 stream (seed 99, never a table's), rendered
at each image size, each passed through every sensor preset's `sense` (sim/sensor.py) as an
observation is: per-image wall and CPU time, median over the scenes. Every sensed training
image and every sensed trial observation pays it once. Needs no data and no network.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from clutterbench.bench import header, write_result
from clutterbench.config import load_params, load_section
from clutterbench.platform_info import cpu_description

SCENES = 20
SIZES = (64, 128, 256)
REPEATS = 5
"""Each image is sensed this many times (the same noise each time: seeded by the image)."""


def bench_sensor(out_dir: Path = Path("reports/bench"), scenes: int = SCENES) -> dict:
    from clutterbench.data.trial_scenes import draw_trial_spec
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.pull import SceneState, world_at
    from clutterbench.sim.render import observe
    from clutterbench.sim.sensor import PRESETS, observation_rng, sense
    from clutterbench.trials.config import TrialsConfig

    params = load_params("params.yaml")
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    stream = trials.streams["ch6_3_10"]
    presets = {k: v for k, v in PRESETS.items() if v is not None}
    rows = []
    for size in SIZES:
        camera = dataclasses.replace(sim.camera, image_size=size)
        observations = []
        for i in range(scenes):
            spec = draw_trial_spec("bench", stream, 99, i, sim.physics, camera, 30)
            world = world_at(spec, SceneState.start(spec), sim.physics, True)
            observations.append(observe(world, camera))
        for name, cfg in presets.items():
            walls, cpus = [], []
            for obs in observations:
                t0, c0 = time.perf_counter(), time.process_time()
                for _ in range(REPEATS):
                    sense(obs.depth_m, obs.camera, cfg, observation_rng(0, obs.depth_m))
                walls.append((time.perf_counter() - t0) / REPEATS)
                cpus.append((time.process_time() - c0) / REPEATS)
            rows.append(
                {
                    "image_size": size,
                    "preset": name,
                    "wall_ms_median": 1e3 * float(np.median(walls)),
                    "cpu_ms_median": 1e3 * float(np.median(cpus)),
                }
            )
            print(f"{size} px {name}: {rows[-1]['wall_ms_median']:.2f} ms per image")
    result: dict = cpu_description() | {"scenes": scenes, "repeats": REPEATS, "rows": rows}
    result["load_average_1min"] = float(__import__("os").getloadavg()[0])
    lines = header("Depth-sensor model: time per image (one core)", result)
    lines += [
        f"The first observations of {scenes} bench scenes of stream ch6_3_10 (seed 99), each "
        f"sensed {REPEATS} times; medians over the scenes. 1-minute load average at the end: "
        f"{result['load_average_1min']:.2f}.",
        "",
        "| image px | preset | wall ms | CPU ms |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {r['image_size']} | {r['preset']} | {r['wall_ms_median']:.2f} | "
        f"{r['cpu_ms_median']:.2f} |"
        for r in rows
    ]
    write_result(out_dir, "sensor", result, lines)
    return result
