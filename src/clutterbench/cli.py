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

User-facing problems (ClutterbenchError) end a command with one red line on stderr,
"error: <message>", and exit code 2. Heavy imports (SAPIEN, matplotlib) happen inside the
commands so that `--help` stays fast.

Default paths (params.yaml, models/, reports/, data/) are those of the project: the nearest
directory at or above the working directory that holds dvc.yaml or params.yaml, else the
repository this package was installed from (`pip install -e`), so the commands work from
any directory. A path given on the command line is taken as it is.
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import json
import math
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
STACK_GAP_M = 0.0005
"""Clearance between stacked boxes (and the bottom box and the floor) in `scene make`."""
DECISION_TOPIC = "/planner/decision"

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
def _print_error(message: str) -> None:
    # soft_wrap: one line however long the message; Text: no markup parsing of the message.
    Console(stderr=True).print(Text(f"error: {message}", style="red"), soft_wrap=True)


@contextlib.contextmanager
def _user_errors() -> Iterator[None]:
    """Turn a ClutterbenchError into the one-line error and exit code 2."""
    try:
        yield
    except ClutterbenchError as exc:
        _print_error(str(exc))
        raise typer.Exit(EXIT_USER_ERROR) from None


def main() -> None:
    """Console-script entry point (`clutterbench = clutterbench.cli:main`)."""
    try:
        app()
    except ClutterbenchError as exc:  # raised outside a command body (should not happen)
        _print_error(str(exc))
        sys.exit(EXIT_USER_ERROR)


# -- shared helpers ---------------------------------------------------------------------------
def _warn_if_not_at_rest(spec: Any, spec_path: Path, cfg: PhysicsConfig | None = None) -> None:
    """One yellow line when the spec's start is not at rest (a box creeps, or floats and
    falls), naming the box and how far it moved with no action; checked on a world of its own,
    so every action still starts from the canonical state, as every label does."""
    from clutterbench.sim.labelling import creep_warning

    warning = creep_warning(spec, cfg or _physics_config(), str(spec_path))
    if warning is not None:
        Console(stderr=True).print(Text(warning, style="yellow"), soft_wrap=True)


PACKAGE_REPO = Path(__file__).resolve().parents[2]
"""The repository the package lives in when installed editable (src/clutterbench/cli.py)."""


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


def _default_path(given: Path | None, relative: str) -> Path:
    """`given` as it is; if None, `relative` inside the project (or the working directory)."""
    if given is not None:
        return given
    root = project_root()
    return root / relative if root is not None else Path(relative)


def _require_file(path: Path, flag: str, made_by: str) -> Path:
    """`path` if it is a file; else one line naming the flag that sets it."""
    if path.is_dir():
        raise ClutterbenchError(f"{flag} {path}: is a directory, not a file")
    if not path.exists():
        raise ClutterbenchError(f"{flag} {path}: not found; pass {flag} PATH ({made_by})")
    return path


def _check_out_file(path: Path, flag: str, example: str) -> Path:
    """Refuse an output path that is a directory before any work is done."""
    if path.is_dir():
        raise ClutterbenchError(
            f"{flag} {path}: is a directory; give a file name, e.g. {path / example}"
        )
    return path


def _project_params() -> dict[str, Any]:
    """The project's params.yaml ({} when there is none)."""
    from clutterbench.config import load_params

    root = project_root()
    if root is None or not (root / "params.yaml").is_file():
        return {}
    return load_params(root / "params.yaml")


def _physics_config() -> PhysicsConfig:
    """Physics parameters: `sim.physics` of the project's params.yaml, else defaults."""
    from clutterbench.config import load_section
    from clutterbench.sim.config import PhysicsConfig, SimConfig

    params = _project_params()
    if "sim" in params:
        return load_section(SimConfig, "sim", params).physics
    return PhysicsConfig()


def _camera_config() -> CameraConfig:
    """The camera of the project's params.yaml (`sim.camera`), else defaults."""
    from clutterbench.config import load_section
    from clutterbench.sim.config import CameraConfig, SimConfig

    params = _project_params()
    if "sim" in params:
        return load_section(SimConfig, "sim", params).camera
    return CameraConfig()


def _box_names(n: int) -> list[str]:
    return [f"box_{i}" for i in range(n)]


# -- scene show ---------------------------------------------------------------------------------
def _instance_rgb(instance: np.ndarray) -> np.ndarray:
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


def _write_scene_png(path: Path, depth_m: np.ndarray, instance: np.ndarray, title: str) -> None:
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

    ax_i.imshow(_instance_rgb(instance), interpolation="nearest")
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


@scene_app.command("show")
def scene_show(
    spec_path: Annotated[Path, typer.Argument(metavar="SPEC.json", help="Scene spec to render.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="PNG to write (depth | instance).")],
) -> None:
    """Render a spec's depth and instance images (no physics step) into one PNG."""
    with _user_errors():
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.render import render_depth_instance
        from clutterbench.sim.spec import SceneSpec

        _check_out_file(out, "--out", "scene.png")
        spec = SceneSpec.load(spec_path)
        _warn_if_not_at_rest(spec, spec_path)
        world = BoxWorld.from_spec(spec, _physics_config(), render=True)
        depth_m, instance = render_depth_instance(world, spec.camera)
        _write_scene_png(
            out, depth_m, instance, f"{spec_path.name}: {spec.n} boxes ({spec.family})"
        )
        typer.echo(f"wrote {out}")


# -- scene act ----------------------------------------------------------------------------------
def _check_indices(n: int, target: int, support: int | None, flag: str = "--remove") -> None:
    if not 0 <= target < n:
        raise ClutterbenchError(f"{flag} {target}: no such box (the scene has boxes 0..{n - 1})")
    if support is not None:
        if not 0 <= support < n:
            raise ClutterbenchError(
                f"--support {support}: no such box (the scene has boxes 0..{n - 1})"
            )
        if support == target:
            raise ClutterbenchError(f"--support {support}: must differ from the removed box")


def _outcome_objects(disp: np.ndarray, target: int, threshold_m: float) -> list[dict[str, Any]]:
    objects = []
    for i, d in enumerate(disp):
        if i == target:
            objects.append({"index": i, "displacement_m": None, "moved": None})
            continue
        objects.append({"index": i, "displacement_m": float(d), "moved": bool(d > threshold_m)})
    return objects


@scene_app.command("act")
def scene_act(
    spec_path: Annotated[Path, typer.Argument(metavar="SPEC.json", help="Scene spec to act on.")],
    remove: Annotated[int, typer.Option("--remove", metavar="K", help="Box to take out.")],
    support: Annotated[
        int | None, typer.Option("--support", metavar="J", help="Box held fixed during the action.")
    ] = None,
    pull: Annotated[
        bool,
        typer.Option(
            "--pull", help="Pull the box out toward the camera instead of lifting it out."
        ),
    ] = False,
    threshold_m: Annotated[
        float, typer.Option("--threshold-m", help="A box moved if displaced more than this (m).")
    ] = 0.005,
    mcap: Annotated[
        Path | None,
        typer.Option(
            "--mcap", help="Also write the episode as an MCAP log (renders before and after)."
        ),
    ] = None,
) -> None:
    """Remove (or pull) one box, let the scene settle, print each box's displacement as JSON."""
    with _user_errors():
        from clutterbench.sim.labelling import act_on_spec
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.spec import SceneSpec

        if not (math.isfinite(threshold_m) and threshold_m >= 0):
            raise ClutterbenchError(f"--threshold-m {threshold_m}: must be a number >= 0")
        if mcap is not None:
            _check_out_file(mcap, "--mcap", "episode.mcap")
        spec = SceneSpec.load(spec_path)
        _check_indices(spec.n, remove, support)
        cfg = _physics_config()
        _warn_if_not_at_rest(spec, spec_path, cfg)
        world = BoxWorld.from_spec(spec, cfg, render=mcap is not None)
        action = "pull" if pull else "remove"
        decision = {"action": action, "target": remove, "support": support}

        episode = contextlib.nullcontext()
        if mcap is not None:
            from clutterbench.logs.mcap_episode import EpisodeWriter

            episode = EpisodeWriter(
                mcap,
                metadata={
                    "spec": spec_path.name,
                    "family": spec.family,
                    "n_boxes": spec.n,
                    "threshold_m": threshold_m,
                    "timestep_s": cfg.timestep_s,
                },
            )
        with episode as ep:
            if ep is not None:
                ep.write_scene(0.0, spec.sizes_m, spec.shelf.boards(), _box_names(spec.n))
                _log_snapshot(ep, world, spec, 0.0)
                ep.write_json(0.0, DECISION_TOPIC, decision)
            disp = act_on_spec(spec, cfg, action, remove, support, world=world)
            objects = _outcome_objects(disp, remove, threshold_m)
            moved = [o["index"] for o in objects if o["moved"]]
            if ep is not None:
                t_end = world.steps_taken * cfg.timestep_s
                if world.removed:
                    names = _box_names(world.n)
                    ep.delete_scene_entities(t_end, [names[k] for k in sorted(world.removed)])
                _log_snapshot(ep, world, spec, t_end)
                ep.set_outcome(
                    {
                        **{k: str(v) for k, v in decision.items()},
                        "moved_count": len(moved),
                        "moved": ",".join(map(str, moved)),
                        "sim_time_s": world.steps_taken * cfg.timestep_s,
                    }
                )
        typer.echo(json.dumps({**decision, "threshold_m": threshold_m, "objects": objects}))


def _log_snapshot(ep: Any, world: Any, spec: Any, t_s: float) -> None:
    from clutterbench.sim.render import camera_model, render_depth_instance

    depth_m, instance = render_depth_instance(world, spec.camera)
    cam = camera_model(world, spec.camera)
    ep.write_camera(t_s, cam.K, cam.T_world_from_cam, depth_m.shape[1], depth_m.shape[0])
    ep.write_depth(t_s, depth_m)
    ep.write_instance(t_s, instance)
    ep.write_poses(t_s, _box_names(world.n), world.poses())


# -- scene make ---------------------------------------------------------------------------------
@scene_app.command("make")
def scene_make(
    out: Annotated[Path, typer.Argument(metavar="OUT.json", help="Spec to write.")],
    stack: Annotated[
        int | None, typer.Option("--stack", metavar="N", help="A straight stack of N boxes.")
    ] = None,
    size_mm: Annotated[
        tuple[float, float, float],
        typer.Option(
            "--size-mm", metavar="H W D", help="With --stack: box height, width, depth (mm)."
        ),
    ] = (20.0, 100.0, 100.0),
    family: Annotated[
        str | None,
        typer.Option(
            "--family", metavar="F", help="A scene of this family (as the datasets draw them)."
        ),
    ] = None,
    seed: Annotated[
        int, typer.Option("--seed", metavar="N", help="With --family: the scene's seed.")
    ] = 0,
    n_objects: Annotated[
        int | None,
        typer.Option(
            "--n-objects", metavar="K", help="With --family: number of boxes (default: 3-10)."
        ),
    ] = None,
    catalogue: Annotated[
        str,
        typer.Option("--catalogue", help="With --family: box catalogue (same | various | new)."),
    ] = "various",
) -> None:
    """Write a settled spec: N identical boxes stacked straight up at the shelf's centre
    (--stack), or a scene of a family drawn from a seed (--family)."""
    with _user_errors():
        _check_out_file(out, "OUT.json", "scene.json")
        if (stack is None) == (family is None):
            raise ClutterbenchError("give one of --stack N or --family F")
        if family is not None:
            _make_family_scene(out, family, seed, n_objects, catalogue)
        else:
            assert stack is not None
            _make_stack(out, stack, size_mm)


def _make_stack(out: Path, stack: int, size_mm: tuple[float, float, float]) -> None:
    import numpy as np

    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.shelf import Shelf
    from clutterbench.sim.spec import SceneSpec

    h, w, d = (v / 1000.0 for v in size_mm)
    shelf = Shelf()
    if stack < 1:
        raise ClutterbenchError(f"--stack {stack}: need at least one box")
    if min(h, w, d) <= 0:
        raise ClutterbenchError(f"--size-mm {size_mm}: sizes must be positive")
    if w > shelf.width_m or d > shelf.depth_m:
        raise ClutterbenchError(
            f"--size-mm {size_mm}: footprint does not fit the shelf "
            f"({shelf.width_m * 1000:g} x {shelf.depth_m * 1000:g} mm)"
        )
    if stack * (h + STACK_GAP_M) > shelf.height_m:
        raise ClutterbenchError(
            f"--stack {stack}: a stack of {stack} x {size_mm[0]:g} mm "
            f"does not fit under the shelf top ({shelf.height_m * 1000:g} mm)"
        )
    size = np.array([d, w, h])  # local extents (x, y, z)
    world = BoxWorld(shelf, _physics_config(), render=False)
    for k in range(stack):
        z = (k + 1) * STACK_GAP_M + (k + 0.5) * h
        world.add_box(size, np.array([shelf.depth_m / 2, 0.0, z, 1.0, 0.0, 0.0, 0.0]))
    result = world.settle()
    if not result.at_rest:
        raise ClutterbenchError(f"the stack of {stack} did not come to rest")
    if not np.all(shelf.contains(world.positions())):
        raise ClutterbenchError(f"a box of the stack of {stack} fell off the shelf")
    spec = SceneSpec(
        sizes_m=np.array(world.sizes_m),
        poses=world.poses(),
        shelf=shelf,
        family="stack",
        meta={
            "stack": stack,
            "size_mm": list(size_mm),
            "gap_mm": STACK_GAP_M * 1000,
            "settle_steps": result.steps,
        },
    )
    spec.save(out)
    typer.echo(f"wrote {out} ({stack} boxes, settled in {result.steps} steps)")


FAMILY_N_OBJECTS = (3, 10)
"""`scene make --family`: the range the number of boxes is drawn from without --n-objects."""
FAMILY_MAX_ATTEMPTS = 30
"""`scene make --family`: placements tried before giving up (as generate.max_attempts)."""


def _make_family_scene(
    out: Path, family: str, seed: int, n_objects: int | None, catalogue: str
) -> None:
    """A settled scene of `family`, drawn as the datasets and trial streams draw theirs: the
    box count once from the seed, then placements until one comes to rest on the shelf."""
    from clutterbench.sim.catalog import CATALOGUES
    from clutterbench.sim.config import FAMILY_NAMES
    from clutterbench.sim.labelling import draw_settled_spec
    from clutterbench.sim.shelf import Shelf

    if family not in FAMILY_NAMES:
        raise ClutterbenchError(f"--family {family}: not one of {', '.join(FAMILY_NAMES)}")
    if catalogue not in CATALOGUES:
        raise ClutterbenchError(f"--catalogue {catalogue}: not one of {', '.join(CATALOGUES)}")
    if seed < 0:
        raise ClutterbenchError(f"--seed {seed}: must be >= 0")
    if n_objects is not None and not 1 <= n_objects <= 30:
        raise ClutterbenchError(f"--n-objects {n_objects}: must be between 1 and 30")
    n_range = (n_objects, n_objects) if n_objects is not None else FAMILY_N_OBJECTS
    try:
        spec = draw_settled_spec(
            seed=seed,
            key=f"cli/{family}",
            index=0,
            families={family: 1.0},
            n_objects=n_range,
            catalogue=catalogue,
            physics=_physics_config(),
            camera=_camera_config(),
            max_attempts=FAMILY_MAX_ATTEMPTS,
            shelf=Shelf(),
            meta={"catalogue": catalogue},
        )
    except ClutterbenchError as exc:
        raise ClutterbenchError(
            f"--family {family}: no settled scene ({exc}); try another --seed or fewer --n-objects"
        ) from None
    spec.save(out)
    typer.echo(
        f"wrote {out} ({family}, {spec.n} boxes, seed {seed}, attempt {spec.meta['attempt']})"
    )


# -- scene get ----------------------------------------------------------------------------------
@scene_app.command("get")
def scene_get(
    dataset: Annotated[str, typer.Argument(metavar="DATASET", help="generate.datasets entry.")],
    index: Annotated[int, typer.Argument(metavar="INDEX", help="Scene index in the dataset.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Spec (JSON) to write.")],
) -> None:
    """Write the spec of a dataset's scene: from its shard in data/generate/DATASET/ when
    there is one, else regenerated alone from (base.seed, DATASET, INDEX) and params.yaml."""
    with _user_errors():
        from clutterbench.sim.spec import SceneSpec

        _check_out_file(out, "--out", f"{dataset}_{index}.json")
        root = project_root()
        data_dir = (root or Path(".")) / "data" / "generate" / dataset
        stored = _spec_from_shards(data_dir, index)
        if stored is not None:
            text, shard = stored
            spec, source = (
                SceneSpec.from_json(text, where=f"{shard} scene {index}"),
                f"from {shard}",
            )
        else:
            spec, source = _regenerate_spec(root, dataset, index)
        spec.save(out)
        typer.echo(
            f"wrote {out} ({dataset} scene {index}: {spec.n} boxes, {spec.family}, {source})"
        )


def _spec_from_shards(data_dir: Path, index: int) -> tuple[str, Path] | None:
    """(spec JSON, shard) of scene `index` if a shard in `data_dir` holds it."""
    from clutterbench.io import load_npz

    for shard in sorted(data_dir.glob("shard-*.npz")):
        indices = load_npz(shard, ["scene_index"])["scene_index"]
        rows = [r for r, i in enumerate(indices.tolist()) if i == index]
        if rows:
            return str(load_npz(shard, ["spec_json"])["spec_json"][rows[0]]), shard
    return None


def _regenerate_spec(root: Path | None, dataset: str, index: int) -> tuple[Any, str]:
    """Scene `index` of `dataset` regenerated as the generate stage makes it."""
    import dataclasses

    from clutterbench.config import load_base, load_section
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import label_scene
    from clutterbench.sim.config import SimConfig

    params = _project_params()
    if "generate" not in params:
        where = root / "params.yaml" if root is not None else "params.yaml"
        raise ClutterbenchError(
            f"{where}: not found or without a generate section; run this in the project "
            "(the directory holding dvc.yaml and params.yaml)"
        )
    gen = load_section(GenerateConfig, "generate", params)
    if dataset not in gen.datasets:
        raise ClutterbenchError(
            f"DATASET {dataset}: no such dataset (known: {', '.join(gen.datasets)})"
        )
    ds = gen.datasets[dataset]
    if not 0 <= index < ds.n_scenes:
        raise ClutterbenchError(f"INDEX {index}: dataset {dataset} has scenes 0..{ds.n_scenes - 1}")
    seed = load_base(params).seed
    # The spec is settled before any label is simulated: leave out the (slow) pull labels.
    scene = label_scene(
        dataset,
        dataclasses.replace(ds, pulls=False),
        load_section(SimConfig, "sim", params),
        seed,
        index,
        gen.max_attempts,
    )
    return scene.spec, f"regenerated from seed {seed}: no shard holds it"


# -- plan ---------------------------------------------------------------------------------------
@app.command("plan")
def plan(
    spec_path: Annotated[Path, typer.Argument(metavar="SPEC.json", help="Scene spec to plan on.")],
    target: Annotated[int, typer.Option("--target", metavar="K", help="Box to extract.")],
    execute: Annotated[
        bool, typer.Option("--execute", help="Run the plan in simulation and judge it.")
    ] = False,
    planner: Annotated[
        str,
        typer.Option(
            "--planner",
            help="multi_step | bimanual | single_step | pull_target | oracle | oracle_hold | "
            "random (only multi_step and bimanual need the collapse predictor)",
        ),
    ] = "multi_step",
    rule: Annotated[
        str, typer.Option("--rule", help="Support rule: coverage_gap | coverage | iou | iou_gap.")
    ] = "coverage_gap",
    model: Annotated[
        Path | None,
        typer.Option(
            "--model", help="Collapse predictor checkpoint (default: models/cp_focal/best.pt)."
        ),
    ] = None,
    thresholds: Annotated[
        Path | None,
        typer.Option(
            "--thresholds",
            help="Val-chosen thresholds of the support stage "
            "(default: reports/support/thresholds.json).",
        ),
    ] = None,
    mcap: Annotated[
        Path | None, typer.Option("--mcap", help="With --execute: write the episode as MCAP.")
    ] = None,
) -> None:
    """Infer the support graph of one scene (thesis 6.2.2), print it beside the physics truth
    with the extraction order and the bimanual option as JSON; --execute runs the plan."""
    with _user_errors():
        import numpy as np

        from clutterbench.config import load_section
        from clutterbench.io import read_json
        from clutterbench.planning.cpg import bimanual_plan, build_cpg, extraction_order
        from clutterbench.planning.extraction import CollapseGraphPlanner
        from clutterbench.planning.support import SupportParams
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.render import observe
        from clutterbench.sim.spec import SceneSpec
        from clutterbench.trials.ch6 import PLANNERS, ch6_jobs, load_predictor, run_extraction
        from clutterbench.trials.config import ConditionConfig, TrialsConfig
        from clutterbench.trials.harness import write_mcap
        from clutterbench.trials.scenes import truth_moved_contact

        if planner not in PLANNERS:  # the registry (built-in planners and registered ones)
            raise ClutterbenchError(f"--planner {planner}: not one of {', '.join(PLANNERS)}")
        if rule not in ("coverage", "iou", "coverage_gap", "iou_gap"):
            raise ClutterbenchError(
                f"--rule {rule}: not one of coverage, iou, coverage_gap, iou_gap"
            )
        if mcap is not None:
            _check_out_file(mcap, "--mcap", "episode.mcap")
        spec = SceneSpec.load(spec_path)
        _check_indices(spec.n, target, None, "--target")
        physics = _physics_config()
        _warn_if_not_at_rest(spec, spec_path, physics)
        params = _project_params()
        trials = (
            load_section(TrialsConfig, "trials", params) if "trials" in params else TrialsConfig()
        )
        # The collapse predictor and the support thresholds are needed by the CP planners
        # (and to print the inferred graph); oracle, random and pull_target run without them.
        model_path = _default_path(model, f"models/{trials.ch6.model}/best.pt")
        thresholds_path = _default_path(thresholds, "reports/support/thresholds.json")
        use_cp = planner in ("multi_step", "bimanual") or (
            model is not None or (model_path.exists() and thresholds_path.exists())
        )
        obs = observe(BoxWorld.from_spec(spec, physics, render=True), spec.camera)
        if target not in obs.visible_boxes(trials.ch6.min_pixels):
            raise ClutterbenchError(f"--target {target}: the camera does not see that box")
        moved, contact = truth_moved_contact(spec, physics, trials.ch6.moved_threshold_m)
        out: dict[str, Any] = {
            "target": target,
            "visible": obs.visible_boxes(trials.ch6.min_pixels),
            "true_edges": [
                {"supporter": int(a), "supported": int(b)}
                for a, b in zip(*np.nonzero(moved & contact))
            ],
        }
        support, cp_max = None, 0.0
        if use_cp:
            model_path = _require_file(
                model_path, "--model", "a checkpoint; `dvc repro train@cp_focal` makes the default"
            )
            thresholds_path = _require_file(
                thresholds_path, "--thresholds", "`dvc repro support` makes the default"
            )
            chosen = read_json(thresholds_path)
            if not isinstance(chosen, dict) or rule not in chosen.get("chosen", {}):
                raise ClutterbenchError(f"{thresholds_path}: no thresholds for rule '{rule}'")
            support = SupportParams(**chosen["chosen"][rule])
            cp_max = trials.ch6.cp_max if trials.ch6.cp_max is not None else support.score_threshold
            predict = load_predictor(model_path, spec.camera.image_size)
            cp = CollapseGraphPlanner(predict, support, cp_max, trials.ch6.min_pixels)
            edges = cp.support_edges(obs)
            graph = build_cpg(edges, target)
            bim = bimanual_plan(graph, target)
            out |= {
                "thresholds": chosen["chosen"][rule],
                "inferred_edges": [
                    {"supporter": e.supporter, "supported": e.supported, "score": round(e.score, 4)}
                    for e in edges
                ],
                "extraction_order": extraction_order(graph, target),
                "bimanual": {
                    "hold": bim.hold,
                    "pull": bim.pull,
                    "steps_to_target": bim.steps_to_target,
                },
            }
        else:
            out["inferred_edges"] = None  # no collapse predictor: pass --model to infer them
        if execute:
            cond = ConditionConfig(planner=planner, stream=next(iter(trials.streams), "cli"))
            streams = trials.streams or {}
            job = ch6_jobs(
                "cli",
                cond,
                trials,
                streams.get(cond.stream),
                0,
                physics,
                spec.camera,
                support,
                cp_max,
                model_path,
            )[0]
            job["ch4_model_path"] = (
                _require_file(
                    _default_path(None, str(job["ch4_model_path"])),
                    "ch4 model",
                    f"`dvc repro train@{trials.ch6.ch4_model}` makes it",
                )
                if planner == "single_step"
                else job["ch4_model_path"]
            )
            result = run_extraction(spec, job, target)
            if mcap is not None:
                write_mcap(mcap, [result], {"spec": spec_path.name, "planner": planner})
            rec = result.record
            out["execute"] = {
                k: rec[k]
                for k in (
                    "planner",
                    "success",
                    "target_out",
                    "others_still",
                    "end",
                    "n_disturbed",
                    "disturbance_m",
                    "aborted_before_motion",
                    "aborted_after_motion",
                    "steps",
                )
            }
        typer.echo(json.dumps(out))


@app.command("replenish")
def replenish(
    spec_path: Annotated[Path, typer.Argument(metavar="SPEC.json", help="Scene spec to fill.")],
    box: Annotated[
        str, typer.Option("--box", metavar="W,D,H", help="New box: width, depth, height in mm.")
    ],
    execute: Annotated[
        bool, typer.Option("--execute", help="Run the plan in simulation and judge it.")
    ] = False,
    planner: Annotated[
        str,
        typer.Option(
            "--planner",
            help="replenish (with collapse prediction) | no_collapse | random | oracle",
        ),
    ] = "replenish",
    perception: Annotated[
        str,
        typer.Option(
            "--perception",
            help="clusters (the generator's ground truth) | detector (models/detector)",
        ),
    ] = "clusters",
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Collapse map network (default: models/cmn_bs32/best.pt)."),
    ] = None,
    mcap: Annotated[
        Path | None, typer.Option("--mcap", help="With --execute: write the episode as MCAP.")
    ] = None,
) -> None:
    """Plan the replenishment of one scene with a box of known size (thesis 5.2.3): print the
    clusters, the candidates, the branch taken and its move as JSON; --execute runs it and
    prints the judged outcome."""
    with _user_errors():
        import numpy as np

        from clutterbench.config import load_section
        from clutterbench.planning.replenish import ReplenishPlanner
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.render import observe
        from clutterbench.sim.spec import SceneSpec
        from clutterbench.trials import ch5
        from clutterbench.trials.config import (
            CH5_PLANNERS,
            Ch5ConditionConfig,
            SceneStreamConfig,
            TrialsConfig,
        )
        from clutterbench.trials.harness import write_mcap
        from clutterbench.trials.protocol import SceneState

        try:
            w, d, h = (float(v) / 1000.0 for v in box.split(","))
        except ValueError:
            raise ClutterbenchError(f"--box {box}: expected W,D,H in mm, e.g. 100,120,30") from None
        if min(w, d, h) <= 0:
            raise ClutterbenchError(f"--box {box}: sizes must be positive")
        if planner not in CH5_PLANNERS:
            raise ClutterbenchError(f"--planner {planner}: not one of {', '.join(CH5_PLANNERS)}")
        if perception not in ("clusters", "detector"):
            raise ClutterbenchError(f"--perception {perception}: not clusters or detector")
        if mcap is not None:
            _check_out_file(mcap, "--mcap", "episode.mcap")
        size_m = np.array([d, w, h])
        spec = SceneSpec.load(spec_path)
        physics = _physics_config()
        _warn_if_not_at_rest(spec, spec_path, physics)
        params = _project_params()
        trials = (
            load_section(TrialsConfig, "trials", params) if "trials" in params else TrialsConfig()
        )
        model_path = _default_path(model, f"models/{trials.ch5.model}/best.pt")
        if planner == "replenish":
            _require_file(model_path, "--model", f"`dvc repro train@{trials.ch5.model}` makes it")
        detector = _default_path(None, "models/detector/best.pt")
        if perception == "detector":
            _require_file(detector, "detector", "`dvc repro detector` makes it")
        prob = trials.ch5.prob_threshold
        if prob is None:
            metrics = _default_path(None, f"reports/evaluate/{trials.ch5.model}_ch5/metrics.json")
            prob = (
                float(json.loads(metrics.read_text())["val_chosen_threshold"])
                if metrics.exists()
                else 0.5
            )
        cond = Ch5ConditionConfig(planner=planner, stream="cli", perception=perception)
        job = ch5.ch5_jobs(
            "cli",
            cond,
            trials.ch5,
            SceneStreamConfig(families={"shelved": 1.0}),
            0,
            physics,
            spec.camera,
            trials.max_attempts,
            mcap is not None,
            prob,
            "cli",
            collapse_free=trials.collapse_free,
        )[0]
        job["model_path"], job["detector_path"] = model_path, detector
        state = SceneState.start(spec)
        obs = observe(BoxWorld.from_spec(spec, physics, render=True), spec.camera)
        dets = ch5.perceive(job, spec, state, obs)
        out: dict[str, Any] = {"box_mm": [w * 1000, d * 1000, h * 1000], "planner": planner}
        if planner in ("replenish", "no_collapse"):
            cmap = ch5.collapse_map_fn(job) if planner == "replenish" else None
            plan = ReplenishPlanner(ch5.planner_params(job), ch5.space_of(spec), cmap).plan(
                obs, dets, size_m
            )
            out["plan"] = ch5.plan_json(plan) | {"clusters": plan.info["clusters"]}
        if execute:
            result = ch5.replenish(spec, job, size_m)
            if mcap is not None:
                write_mcap(mcap, [result], {"spec": spec_path.name, "planner": planner})
            rec = result.record
            out["execute"] = {
                k: rec[k]
                for k in ("success", "end", "branch", "n_disturbed", "disturbance_m", "steps")
            }
        typer.echo(json.dumps(out))


@app.command("yamakuzushi")
def yamakuzushi(
    seed: Annotated[int, typer.Option("--seed", metavar="N", help="The pile's seed.")] = 0,
    variant: Annotated[
        str,
        typer.Option("--variant", help="convnet | no_convnet | convnet_no_pomdp | random | oracle"),
    ] = "convnet",
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Slide ConvNet (default: models/slide_convnet/best.pt)."),
    ] = None,
    mcap: Annotated[
        Path | None, typer.Option("--mcap", help="Write the game as MCAP (Foxglove).")
    ] = None,
) -> None:
    """Play one Yamakuzushi game (thesis ch. 3) on the pile of --seed: print each slide (the
    piece, direction, ConvNet probability, sensor moves, outcome judged from physics) and how
    the game ended, as JSON lines. Params: `yamakuzushi` of the project's params.yaml."""
    with _user_errors():
        from clutterbench.config import load_section
        from clutterbench.parallel import worker_init
        from clutterbench.trials.ch3 import run_ch3_game
        from clutterbench.trials.ch3_config import VARIANTS, Ch3Config
        from clutterbench.trials.harness import write_mcap

        if variant not in VARIANTS:
            raise ClutterbenchError(f"--variant {variant!r}: not one of {', '.join(VARIANTS)}")
        params = _project_params()
        cfg = load_section(Ch3Config, "yamakuzushi", params) if params else Ch3Config()
        path = None
        if variant in ("convnet", "convnet_no_pomdp"):
            path = _require_file(
                _default_path(model, "models/slide_convnet/best.pt"),
                "--model",
                "dvc repro train_slide",
            )
        if mcap is not None:
            _check_out_file(mcap, "--mcap", "game.mcap")
        worker_init(1)
        job = {
            "variant": variant,
            "game": 0,
            "seed": seed,
            "cfg": cfg,
            "model": None if path is None else str(path),
            "mcap_images": mcap is not None,
        }
        result = run_ch3_game(job)
        for step in result.record["steps"]:
            typer.echo(json.dumps(step))
        head = {k: v for k, v in result.record.items() if k != "steps"}
        typer.echo(json.dumps(head))
        if mcap is not None:
            write_mcap(mcap, [result], {"condition": variant, "seed": str(seed)})


@app.command("yamakuzushi-validate")
def yamakuzushi_validate(
    min_probability: Annotated[
        list[float],
        typer.Option(
            "--min-probability",
            help="A value of yamakuzushi.select.min_probability to play (repeat the option).",
        ),
    ],
    games: Annotated[int, typer.Option("--games", min=1, help="Games per value.")] = 40,
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Slide ConvNet (default: models/slide_convnet/best.pt)."),
    ] = None,
) -> None:
    """Choose `yamakuzushi.select.min_probability` on validation piles (seed stream ch3_val,
    never the games' piles): play --games games with the ConvNet for each value and print
    pieces per game and per-slide success per value, then the value with the most pieces per
    game among those whose per-slide success is at least 90% with 95% confidence (the lower
    end of its interval, a bootstrap over games as in Fig. 3.15's table: the rule the params'
    value comes from)."""
    with _user_errors():
        import dataclasses

        from clutterbench.config import BaseConfig, load_section
        from clutterbench.data.slides import pile_seed
        from clutterbench.trials.ch3 import ch3_jobs, run_ch3_game
        from clutterbench.trials.ch3_config import Ch3Config
        from clutterbench.trials.harness import run_episodes
        from clutterbench.trials.stats import aggregate_games

        for p in min_probability:
            if not 0.0 <= p <= 1.0:
                raise ClutterbenchError(f"--min-probability {p}: not within [0, 1]")
        params = _project_params()
        cfg = load_section(Ch3Config, "yamakuzushi", params) if params else Ch3Config()
        seed = load_section(BaseConfig, "base", params).seed if params else BaseConfig().seed
        path = _require_file(
            _default_path(model, "models/slide_convnet/best.pt"), "--model", "dvc repro train_slide"
        )
        games_cfg = dataclasses.replace(
            cfg.games, n_games=games, variants=("convnet",), mcap_images=False
        )
        jobs = []
        for p in min_probability:
            select = dataclasses.replace(cfg.select, min_probability=p)
            run = dataclasses.replace(cfg, games=games_cfg, select=select)
            for job in ch3_jobs(run, lambda g: pile_seed(seed, "ch3_val", g), str(path)):
                jobs.append(job | {"min_probability": p})
        results = run_episodes("validation games", run_ch3_game, jobs, cfg.games.workers)
        records = [
            r.record | {"condition": f"{job['min_probability']:g}"}
            for r, job in zip(results, jobs, strict=True)
        ]
        summary = aggregate_games(records)
        best = None
        for row in summary.itertuples():
            rate = row.step_success_k / row.step_success_n if row.step_success_n else 0.0
            typer.echo(
                f"min_probability {row.condition}: {row.mean_pieces:.2f} pieces per game, "
                f"per slide {row.step_success_k}/{row.step_success_n} = {rate:.1%} "
                f"[{row.step_success_lo:.1%}, {row.step_success_hi:.1%}], ends: {row.ends}"
            )
            if row.step_success_lo >= 0.9 and (best is None or row.mean_pieces > best[1]):
                best = (row.condition, row.mean_pieces)
        if best is None:
            typer.echo("no value is at >= 90% per slide with 95% confidence on these games")
        else:
            typer.echo(
                f"choice: min_probability {best[0]} (most pieces per game at >= 90% per slide, "
                "interval's lower end)"
            )


@app.command("evaluate-agent")
def evaluate_agent(
    agent: Annotated[
        str,
        typer.Argument(
            metavar="MODULE:FACTORY",
            help="FACTORY(env) -> a policy (obs -> action, or .act(obs)); MODULE: an importable "
            "module or a .py file (e.g. docs/examples/random_agent.py:make_agent).",
        ),
    ],
    stream: Annotated[
        str, typer.Option("--stream", help="Scene stream (a key of trials.streams).")
    ] = "ch6_3_10",
    episodes: Annotated[int, typer.Option("--episodes", min=1, help="Episodes 0..N-1.")] = 20,
    first: Annotated[int, typer.Option("--first", min=0, help="First episode index.")] = 0,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Output root (default: reports/agents): OUT/NAME/records.jsonl"),
    ] = None,
    name: Annotated[
        str | None, typer.Option("--name", help="Condition name (default: FACTORY).")
    ] = None,
    scale: Annotated[
        str | None, typer.Option("--scale", help="Scale profile (default: base.scale).")
    ] = None,
) -> None:
    """Run an agent through ClutterShelfPlan-v1 on episodes of a stream (the trials' scenes
    and targets, the episode protocol, judged from physics) and write the trials' records,
    summary (both success criteria) and MCAP; print the summary's headline."""
    with _user_errors():
        from clutterbench.envs.evaluate import evaluate_agent as run

        out_dir = _default_path(out, "reports/agents")
        if out_dir.exists() and not out_dir.is_dir():
            raise ClutterbenchError(f"--out {out_dir}: is a file, not a directory")
        summary = run(agent, stream, episodes, out_dir, name=name, first=first, scale=scale)
        cond = summary["condition"]
        typer.echo(
            f"{cond} on {summary['stream']} ({summary['episodes']} episodes): "
            f"success (collapse-free) {summary['success_k']}/{summary['success_n']}, "
            f"strict {summary['strict_success_k']}/{summary['strict_success_n']}; "
            f"wrote {out_dir / cond}/records.jsonl, summary.json"
        )


if __name__ == "__main__":
    main()
