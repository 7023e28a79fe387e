"""`clutterbench` command line: inspect, make and act on single scene specs.

    clutterbench --version
    clutterbench scene show SPEC.json --out scene.png
    clutterbench scene act SPEC.json --remove K [--support J] [--pull] [--mcap out.mcap]
    clutterbench scene make OUT.json --stack N [--size-mm H W D]
    clutterbench scene make OUT.json --family F --seed N [--n-objects K] [--catalogue C]
    clutterbench scene get DATASET INDEX --out spec.json
    clutterbench plan SPEC.json --target K [--execute] [--mcap out.mcap]
    clutterbench replenish SPEC.json --box W,D,H [--execute] [--mcap out.mcap]
    clutterbench evaluate-agent MODULE:FACTORY [--stream S] [--episodes N] [--out DIR]
        [--fresh N [--seed S]]
    clutterbench evaluate-predictor MODULE[:FUNCTION] [--name N] [--testset DIR] [--out DIR]
        [--fresh N [--seed S]]
    clutterbench check [PARAMS] [--spec FILE ...]

User-facing problems (ClutterbenchError) end a command with one red line on stderr,
"error: <message>", and exit code 2. Heavy imports (SAPIEN, matplotlib) happen inside the
commands so that `--help` stays fast.

Default paths (params.yaml, models/, reports/, data/) are those of the project: the nearest
directory at or above the working directory that holds dvc.yaml or params.yaml, else the
repository this package was installed from (`pip install -e`), so the commands work from
any directory. A path given on the command line is taken as it is.

One module per command group: `scene` (show, act, make, get), `plan`, `replenish`,
`yamakuzushi`, `agents` (evaluate-agent), `predictors` (evaluate-predictor), `check` (params.yaml
and scene specs checked without data); `common` holds the app, the error handling and the
project paths they share.
"""

from clutterbench.cli import (  # noqa: F401  (commands)
    agents,
    check,
    plan,
    predictors,
    replenish,
    scene,
    yamakuzushi,
)
from clutterbench.cli.common import app, main

__all__ = ["app", "main"]
