"""What every `clutterbench` command shares: the Typer app, the one-red-line error handling
(ClutterbenchError -> "error: <message>", exit 2), the project's default paths and the
params it reads."""

from __future__ import annotations

import contextlib
import importlib.metadata
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.text import Text

from clutterbench.errors import ClutterbenchError

if TYPE_CHECKING:
    import numpy as np

    from clutterbench.sim.config import CameraConfig, PhysicsConfig

EXIT_USER_ERROR = 2

app = typer.Typer(
    help="clutterbench: box-clutter scenes on a shelf.",
    no_args_is_help=True,
    pretty_exceptions_show_locals=False,
)
scene_app = typer.Typer(
    help="Inspect, make and act on one scene spec (JSON).", no_args_is_help=True
)
app.add_typer(scene_app, name="scene")


def _package_version() -> str:
    try:
        return importlib.metadata.version("clutterbench")
    except importlib.metadata.PackageNotFoundError:  # run from a source tree, not installed
        from clutterbench import __version__

        return __version__


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"clutterbench {_package_version()}")
        raise typer.Exit()


@app.callback()
def _main_options(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_print_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """clutterbench: box-clutter scenes on a shelf."""


# -- errors -------------------------------------------------------------------------------------
def print_error(message: str) -> None:
    # soft_wrap: one line however long the message; Text: no markup parsing of the message.
    Console(stderr=True).print(Text(f"error: {message}", style="red"), soft_wrap=True)


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Turn a ClutterbenchError into the one-line error and exit code 2."""
    try:
        yield
    except ClutterbenchError as exc:
        print_error(str(exc))
        raise typer.Exit(EXIT_USER_ERROR) from None


def main() -> None:
    """Console-script entry point (`clutterbench = clutterbench.cli:main`)."""
    try:
        app()
    except ClutterbenchError as exc:  # raised outside a command body (should not happen)
        print_error(str(exc))
        sys.exit(EXIT_USER_ERROR)


# -- shared helpers ---------------------------------------------------------------------------
def warn_if_not_at_rest(spec: Any, spec_path: Path, cfg: PhysicsConfig | None = None) -> None:
    """One yellow line when the spec's start is not at rest (a box creeps, or floats and
    falls), naming the box and how far it moved with no action; checked on a world of its own,
    so every action still starts from the canonical state, as every label does."""
    from clutterbench.sim.labelling import creep_warning

    warning = creep_warning(spec, cfg or physics_config(), str(spec_path))
    if warning is not None:
        Console(stderr=True).print(Text(warning, style="yellow"), soft_wrap=True)


PACKAGE_REPO = Path(__file__).resolve().parents[3]
"""The repository the package lives in when installed editable (src/clutterbench/cli/common.py)."""


def project_root() -> Path | None:
    """The project the command works in: the nearest directory at or above the working
    directory holding dvc.yaml or params.yaml, else the package's own repository (if it is
    one), else None."""
    cwd = Path.cwd().resolve()
    for d in (cwd, *cwd.parents):
        if (d / "dvc.yaml").is_file() or (d / "params.yaml").is_file():
            return d
    if (PACKAGE_REPO / "dvc.yaml").is_file():
        return PACKAGE_REPO
    return None


def default_path(given: Path | None, relative: str) -> Path:
    """`given` as it is; if None, `relative` inside the project (or the working directory)."""
    if given is not None:
        return given
    root = project_root()
    return root / relative if root is not None else Path(relative)


def require_file(path: Path, flag: str, made_by: str) -> Path:
    """`path` if it is a file; else one line naming the flag that sets it."""
    if path.is_dir():
        raise ClutterbenchError(f"{flag} {path}: is a directory, not a file")
    if not path.exists():
        raise ClutterbenchError(f"{flag} {path}: not found; pass {flag} PATH ({made_by})")
    return path


def check_out_file(path: Path, flag: str, example: str) -> Path:
    """Refuse an output path that is a directory before any work is done."""
    if path.is_dir():
        raise ClutterbenchError(
            f"{flag} {path}: is a directory; give a file name, e.g. {path / example}"
        )
    return path


def project_params() -> dict[str, Any]:
    """The project's params.yaml ({} when there is none)."""
    from clutterbench.config import load_params

    root = project_root()
    if root is None or not (root / "params.yaml").is_file():
        return {}
    return load_params(root / "params.yaml")


def physics_config() -> PhysicsConfig:
    """Physics parameters: `sim.physics` of the project's params.yaml, else defaults."""
    from clutterbench.config import load_section
    from clutterbench.sim.config import PhysicsConfig, SimConfig

    params = project_params()
    if "sim" in params:
        return load_section(SimConfig, "sim", params).physics
    return PhysicsConfig()


def camera_config() -> CameraConfig:
    """The camera of the project's params.yaml (`sim.camera`), else defaults."""
    from clutterbench.config import load_section
    from clutterbench.sim.config import CameraConfig, SimConfig

    params = project_params()
    if "sim" in params:
        return load_section(SimConfig, "sim", params).camera
    return CameraConfig()


def box_names(n: int) -> list[str]:
    return [f"box_{i}" for i in range(n)]


# -- scene show ---------------------------------------------------------------------------------
def instance_rgb(instance: np.ndarray) -> np.ndarray:
    """Instance ids -> RGB float image: a distinct colour per id, background black."""
    import numpy as np
    from matplotlib import colormaps

    # tab20's ten dark hues first, then its ten light ones: neighbouring ids differ in hue.
    tab20 = colormaps["tab20"]
    palette = [tab20(i)[:3] for i in (*range(0, 20, 2), *range(1, 20, 2))]
    rgb = np.zeros((*instance.shape, 3))
    for k in np.unique(instance):
        if k == 0:
            continue
        rgb[instance == k] = palette[(int(k) - 1) % len(palette)]
    return rgb


def write_scene_png(path: Path, depth_m: np.ndarray, instance: np.ndarray, title: str) -> None:
    import numpy as np
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from clutterbench.io import atomic_path

    fig = Figure(figsize=(10.0, 4.6), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)  # Agg, without pyplot's global state
    ax_d, ax_i = fig.subplots(1, 2)

    cmap = colormaps["viridis"].with_extremes(bad="black")
    valid = depth_m > 0
    shown = np.ma.masked_where(~valid, depth_m)
    vmin, vmax = (
        (float(depth_m[valid].min()), float(depth_m[valid].max())) if valid.any() else (0.0, 1.0)
    )
    im = ax_d.imshow(shown, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    ax_d.set_title("depth (black = no return)")
    fig.colorbar(im, ax=ax_d, label="depth (m)", shrink=0.9)

    ax_i.imshow(instance_rgb(instance), interpolation="nearest")
    ax_i.set_title("boxes (the index --remove takes)")
    for k in np.unique(instance):
        if k == 0:
            continue
        rows, cols = np.nonzero(instance == k)
        ax_i.text(
            float(cols.mean()),
            float(rows.mean()),
            str(int(k) - 1),
            color="white",
            ha="center",
            va="center",
            fontsize=9,
            fontweight="bold",
            bbox={"facecolor": "black", "alpha": 0.5, "pad": 1, "linewidth": 0},
        )
    for ax in (ax_d, ax_i):
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")


def check_indices(n: int, target: int, support: int | None, flag: str = "--remove") -> None:
    if not 0 <= target < n:
        raise ClutterbenchError(f"{flag} {target}: no such box (the scene has boxes 0..{n - 1})")
    if support is not None:
        if not 0 <= support < n:
            raise ClutterbenchError(
                f"--support {support}: no such box (the scene has boxes 0..{n - 1})"
            )
        if support == target:
            raise ClutterbenchError(f"--support {support}: must differ from the removed box")


FreshSeed = Annotated[
    int | None,
    typer.Option(
        "--seed",
        min=0,
        help="With --fresh: the seed (default: drawn from os.urandom; give one only to "
        "reproduce a fresh run or score).",
    ),
]
"""evaluate-agent's and evaluate-predictor's --seed (with --fresh)."""
