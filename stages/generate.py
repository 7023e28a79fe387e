"""Stage generate@<dataset>: labelled shelf scenes, sharded, parallel, resumable."""

import sys
from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.data.generate import generate_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.parallel import ParallelConfig
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.config import TrialsConfig


def generate(params: dict, base: BaseConfig) -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else ""
    gen = load_section(GenerateConfig, "generate", params)
    sim = load_section(SimConfig, "sim", params)
    if name not in gen.datasets:
        raise ClutterbenchError(
            f"generate.datasets.{name}: no such dataset (known: {', '.join(gen.datasets)})"
        )
    # a dataset with pull outcomes pulls as the ch. 6 trials do (the same executor and params)
    ch6 = load_section(TrialsConfig, "trials", params).ch6
    pull = (ch6.pull_increment_m, ch6.grasp_lift_m)
    parallel = load_section(ParallelConfig, "parallel", params)
    manifest = generate_dataset(
        name, gen.datasets[name], gen, sim, base.seed, Path("data/generate") / name, pull, parallel
    )
    print(f"{name}: {manifest['n_scenes']} scenes, rejected {manifest['rejected']}")


if __name__ == "__main__":
    run_stage(generate)
