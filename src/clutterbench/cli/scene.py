"""`clutterbench scene show | act | make | get`: one scene spec (JSON) at a time."""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from clutterbench.cli.common import (
    box_names,
    camera_config,
    check_indices,
    check_out_file,
    physics_config,
    project_params,
    project_root,
    scene_app,
    user_errors,
    warn_if_not_at_rest,
    write_scene_png,
)
from clutterbench.errors import ClutterbenchError

if TYPE_CHECKING:
    import numpy as np


STACK_GAP_M = 0.0005
"""Clearance between stacked boxes (and the bottom box and the floor) in `scene make`."""
DECISION_TOPIC = "/planner/decision"


@scene_app.command("show")
def scene_show(
    spec_path: Annotated[Path, typer.Argument(metavar="SPEC.json", help="Scene spec to render.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="PNG to write (depth | instance).")],
) -> None:
    """Render a spec's depth and instance images (no physics step) into one PNG."""
    with user_errors():
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.render import render_depth_instance
        from clutterbench.sim.spec import SceneSpec

        check_out_file(out, "--out", "scene.png")
        spec = SceneSpec.load(spec_path)
        warn_if_not_at_rest(spec, spec_path)
        world = BoxWorld.from_spec(spec, physics_config(), render=True)
        depth_m, instance = render_depth_instance(world, spec.camera)
        write_scene_png(out, depth_m, instance, f"{spec_path.name}: {spec.n} boxes ({spec.family})")
        typer.echo(f"wrote {out}")


# -- scene act ----------------------------------------------------------------------------------
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
    with user_errors():
        from clutterbench.sim.labelling import act_on_spec
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.spec import SceneSpec

        if not (math.isfinite(threshold_m) and threshold_m >= 0):
            raise ClutterbenchError(f"--threshold-m {threshold_m}: must be a number >= 0")
        if mcap is not None:
            check_out_file(mcap, "--mcap", "episode.mcap")
        spec = SceneSpec.load(spec_path)
        check_indices(spec.n, remove, support)
        cfg = physics_config()
        warn_if_not_at_rest(spec, spec_path, cfg)
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
                ep.write_scene(0.0, spec.sizes_m, spec.shelf.boards(), box_names(spec.n))
                _log_snapshot(ep, world, spec, 0.0)
                ep.write_json(0.0, DECISION_TOPIC, decision)
            disp = act_on_spec(spec, cfg, action, remove, support, world=world)
            objects = _outcome_objects(disp, remove, threshold_m)
            moved = [o["index"] for o in objects if o["moved"]]
            if ep is not None:
                t_end = world.steps_taken * cfg.timestep_s
                if world.removed:
                    names = box_names(world.n)
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
    ep.write_poses(t_s, box_names(world.n), world.poses())


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
    with user_errors():
        check_out_file(out, "OUT.json", "scene.json")
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
    world = BoxWorld(shelf, physics_config(), render=False)
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
            physics=physics_config(),
            camera=camera_config(),
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
    with user_errors():
        from clutterbench.sim.spec import SceneSpec

        check_out_file(out, "--out", f"{dataset}_{index}.json")
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

    params = project_params()
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
