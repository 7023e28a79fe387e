"""Stage noise: task noise of the chapter 6 trials (the work: clutterbench.trials.noise.run).
Every replayed condition's recorded episodes in `noise.draws` perturbed worlds, and the robust
search oracles (plans that hold in perturbed worlds) -> reports/noise/."""

from clutterbench.config import BaseConfig, load_section
from clutterbench.parallel import ParallelConfig
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.noise.config import NoiseConfig
from clutterbench.trials.noise.run import run_noise


def noise(params: dict, base: BaseConfig) -> None:
    cfg = load_section(NoiseConfig, "noise", params)
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    parallel = load_section(ParallelConfig, "parallel", params)
    summary = run_noise(base.seed, cfg, trials, sim, parallel)
    for name, row in summary["conditions"].items():
        s = row["success"]
        print(
            f"{name}: table {s['nominal_k']}/{s['n']}, perturbed mean {s['mean_rate']:.3f} "
            f"(sd {s['sd_rate']:.3f}), successes surviving {s['survive']:.2f}"
        )


if __name__ == "__main__":
    run_stage(noise)
