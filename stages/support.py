"""Stage support: thresholds chosen on val scenes, then Table 6.2's evidence on test scenes
(the work: clutterbench.support.run)."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.parallel import ParallelConfig
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.support.config import SupportEvalConfig
from clutterbench.support.run import SupportPaths, run_support
from clutterbench.trials.config import TrialsConfig

OUT = Path("reports/support")
SCENES = Path("data/support")


def support(params: dict, base: BaseConfig) -> None:
    cfg = load_section(SupportEvalConfig, "support", params)
    gen = load_section(GenerateConfig, "generate", params)
    sim = load_section(SimConfig, "sim", params)
    parallel = load_section(ParallelConfig, "parallel", params)  # the test scenes' backend
    if cfg.val_dataset not in gen.datasets:
        raise ClutterbenchError(f"support.val_dataset: unknown dataset '{cfg.val_dataset}'")
    paths = SupportPaths.of(cfg, OUT, SCENES)
    ch6 = load_section(TrialsConfig, "trials", params).ch6  # the trials' pull, fits, fusion
    mean = run_support(params, base.seed, cfg, sim, parallel, paths, ch6)
    for method, r in mean.iterrows():
        print(f"support {method}: precision {r['precision']:.3f} recall {r['recall']:.3f}")


if __name__ == "__main__":
    run_stage(support)
