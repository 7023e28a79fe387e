"""Chapter 3 games of Yamakuzushi (thesis 3.5.2, Fig. 3.15): a pile, then target selection ->
POMDP (observe or slide) -> slide, repeated until a slide fails or nothing is worth sliding.

Every step starts from a fresh world built from the pile's present state (the canonical
start); the planner sees the top camera's picture and, when the POMDP asks, the movable
sensor's pictures from its chosen viewpoints; the slide is simulated and judged from physics
(sim.pile.slide). Variants (trials.ch3_config.VARIANTS):
- convnet: the ConvNet's best pieces (planning.yamakuzushi.convnet_targets), each through the
  POMDP; the first the POMDP slides is slid. A piece refused by the POMDP is skipped; all
  refused, or none above the ConvNet's threshold: the game ends (nothing worth sliding).
- no_convnet: the same with the least-occluded pieces (the thesis' comparison).
- convnet_no_pomdp: the ConvNet's best piece slid at once (the POMDP's share).
- random: a random candidate on a piece, slid at once (floor).
- oracle: every visible piece in every direction simulated from the present state, the first
  success kept (pieces from the highest down); none: the game ends (ceiling: it never makes a
  failing slide).
One record per game (its slides in `steps`); the stage writes one row per slide as well.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench import criteria
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.data.slide_crops import ScanConfig
from clutterbench.denormals import flush_denormals
from clutterbench.observation import Observation
from clutterbench.planning.ch3 import pomdp
from clutterbench.planning.ch3.yamakuzushi import (
    PomdpConfig,
    Target,
    convnet_targets,
    least_occluded_targets,
    random_targets,
)
from clutterbench.shogi_piece import PIECE_SIZE_M
from clutterbench.trials.ch3.config import CONVNET_VARIANTS, Ch3Config
from clutterbench.trials.core.harness import EpisodeLog, EpisodeResult
from clutterbench.trials.core.jobs import EpisodeJob

STEP_S = 1.0
"""Simulated seconds between two logged steps of a game on the MCAP timeline."""
DIGITS = 6
"""POMDP values are recorded to this many decimals: open3d's ICP sums in parallel, so their
last bits may differ from run to run; six decimals keep the records byte-identical."""
_MODEL_CACHE: dict[str, Any] = {}


def _convnet(path: str):
    if path not in _MODEL_CACHE:
        from clutterbench.models.slide_convnet import load_slide_convnet

        _MODEL_CACHE[path] = load_slide_convnet(Path(path))[0]
    return _MODEL_CACHE[path]


def _scene_points(obs: Observation, piece: int) -> tuple[np.ndarray, np.ndarray]:
    """(target points, other object points) of a view, board points left out."""
    pts = obs.camera.depth_to_points(obs.depth_m)
    target = obs.instance == piece + 1
    others = (obs.instance > 0) & ~target
    return pts[target].reshape(-1, 3), pts[others].reshape(-1, 3)


def _eye(obs: Observation) -> np.ndarray:
    return obs.camera.T_world_from_cam[:3, 3].copy()


def run_pomdp(world, target: Target, top: Observation, cfg, log: EpisodeLog, t: float):
    """The thesis' observe-or-slide loop (3.4) for one target: the belief starts uniform and
    is updated with the top view; while observing at the best viewpoint is worth more than
    sliding (eq. 3.3) and observations remain, the sensor moves there and the belief is
    updated. Slid when the POMDP chooses to slide and the flat states hold at least
    pomdp.min_flat_share of the belief; else refused. Returns (slide?, facts for the record,
    time)."""
    from clutterbench.sim.pile import view_observation

    pc: PomdpConfig = cfg.pomdp
    mine, others = _scene_points(top, target.piece)
    centre = mine[:, :2].mean(axis=0) if len(mine) else np.asarray(target.start_xy)
    views = [top]
    b = pomdp.update_belief(
        pomdp.uniform_belief(),
        pomdp.state_weights(mine, centre, pc.e_th_m, eye_m=_eye(top), occluders=others),
    )
    eyes = pomdp.viewpoint_candidates(
        [centre[0], centre[1], 0.0], pc.viewpoint_distances_m, pc.min_elevation_deg
    )
    visited: list[int] = []
    decision = None
    for _ in range(pc.max_observations + 1):
        scene = np.concatenate([_scene_points(v, target.piece)[1] for v in views] + [mine])
        grid = pomdp.occupancy_grid(scene, np.array([_eye(v) for v in views]), centre)
        free = [k for k in range(len(eyes)) if k not in visited]
        decision = pomdp.decide(
            b,
            eyes[free],
            centre,
            grid,
            others,
            reward=pc.reward,
            alpha=pc.alpha,
            beta=pc.beta,
            e_th_m=pc.e_th_m,
        )
        belief = [round(float(v), DIGITS) for v in b]
        log.json(t, "/planner/belief", {"piece": target.piece, "belief": belief})
        if decision.kind == "slide" or len(visited) >= pc.max_observations:
            break
        k = free[decision.viewpoint]
        visited.append(k)
        view = view_observation(world, cfg.camera, eyes[k], np.array([*centre, 0.01]))
        views.append(view)
        t += STEP_S / 4
        log.json(t, "/sensor/viewpoint", {"piece": target.piece, "eye_m": eyes[k].tolist()})
        if log.record_images:
            near, far = cfg.camera.near_m, cfg.camera.far_m
            log.heatmap(t, "/sensor/depth", np.clip((view.depth_m - near) / (far - near), 0, 1))
        seen, occ = _scene_points(view, target.piece)
        b = pomdp.update_belief(
            b, pomdp.state_weights(seen, centre, pc.e_th_m, eye_m=eyes[k], occluders=occ)
        )
    mass = pomdp.belief_mass(b)
    flat = float(b[list(pomdp.SLIDABLE_STATES)].sum() / mass) if mass > 0 else 0.0
    no_fit = mass < pc.min_mass
    if no_fit:
        slide_it = pc.when_no_state_fits == "slide"
    else:
        slide_it = decision.kind == "slide" and flat >= pc.min_flat_share
    facts = {
        "observations": len(visited),
        "belief_mass": round(mass, DIGITS),
        "flat_share": round(flat, DIGITS),
        "most_likely_state": int(np.argmax(b)),
        "pomdp_choice": decision.kind,
        "no_state_fits": bool(no_fit),
        "slide_value": round(decision.slide_value, DIGITS),
    }
    return slide_it, facts, t


def _oracle_choice(poses: np.ndarray, top: Observation, cfg) -> tuple[Target | None, Any, int]:
    """The first successful slide of the visible pieces (highest first) x directions, each
    simulated from a fresh world at `poses`; (target, its result, slides simulated)."""
    from clutterbench.sim.pile import PileWorld, slide

    n_dir = cfg.scan.n_directions
    visible = top.visible_boxes(cfg.select.min_visible_px)
    order = sorted(visible, key=lambda k: -poses[k, 2])
    centre = poses[visible, :2].mean(axis=0) if visible else np.zeros(2)
    tried = 0
    for piece in order:
        # directions nearest to "away from the pile" first: the likely successes come early
        away = np.arctan2(*(poses[piece, :2] - centre)[::-1])
        gap = [abs(np.angle(np.exp(1j * (d * 2 * np.pi / n_dir - away)))) for d in range(n_dir)]
        for d in np.argsort(gap, kind="stable"):
            tried += 1
            world = PileWorld.from_poses(poses, cfg.pile)
            result = slide(world, piece, int(d) * 2 * np.pi / n_dir, cfg.slide)
            if result.success:
                start = (float(poses[piece, 0]), float(poses[piece, 1]))
                return Target(piece, start, int(d)), result, tried
    return None, None, tried


def _targets(variant: str, job: Ch3Job, top: Observation, rng) -> list[Target]:
    cfg = job.cfg
    scan: ScanConfig = cfg.scan
    if variant in CONVNET_VARIANTS:
        with flush_denormals():  # as in training (clutterbench.denormals)
            return convnet_targets(_convnet(job.model), top, scan, cfg.select)
    if variant == "no_convnet":
        return least_occluded_targets(top, scan, cfg.select)
    return random_targets(top, scan, cfg.select, rng)


def run_ch3_game(job: Ch3Job) -> EpisodeResult:
    """One game of one variant on the pile of `job.seed`."""
    from clutterbench.sim.pile import PileWorld, generate_pile, top_observation

    cfg = job.cfg
    spec = generate_pile(cfg.pile, job.seed)
    poses = np.array(spec.poses, dtype=np.float64)
    rng = np.random.default_rng(job.seed + 7)
    log = EpisodeLog(record_images=job.record_images)
    steps: list[dict[str, Any]] = []
    stop: dict[str, Any] = {}
    end = "max_slides"
    t = 0.0
    for step in range(cfg.games.max_slides):
        if not np.isfinite(poses).all(axis=1).any():
            end = "cleared"
            break
        world = PileWorld.from_poses(poses, cfg.pile, render=True)
        top = top_observation(world, cfg.camera)
        _log_observation(log, t, step, poses, top, cfg)
        chosen, result, facts, t = _choose(job, world, top, poses, rng, log, t)
        if chosen is None:
            end = "nothing_worth_sliding"
            stop = {"offered": facts.get("offered", 0), "refused": facts.get("refused", [])}
            log.json(t, "/planner/decision", {"step": step, "action": "stop", **facts})
            break
        result, after, t = _slide(job, step, poses, chosen, result, facts, steps, log, t)
        if not result.success:
            end = "slide_failed"
            break
        poses = after
    if end == "max_slides" and not np.isfinite(poses).all(axis=1).any():
        end = "cleared"
    return EpisodeResult(record=_game_record(job, spec, steps, end, stop), log=log)


def _log_observation(
    log: EpisodeLog, t: float, step: int, poses: np.ndarray, top: Observation, cfg: Ch3Config
) -> None:
    """The pile before a slide: the scene (first step only), the poses and the top view."""
    if step == 0:
        sizes = np.tile(np.array(PIECE_SIZE_M), (len(poses), 1))
        board = (
            "board",
            np.array([*np.asarray(cfg.pile.board_size_m) / 2, 0.005]),
            np.array([0.0, 0.0, -0.005]),
        )
        log.scene(t, sizes, [board], top.camera, top.depth_m.shape)
    log.poses(t, np.nan_to_num(poses), [k for k in range(len(poses)) if np.isnan(poses[k, 0])])
    log.observation(t, top.depth_m, top.instance)


def _choose(
    job: Ch3Job,
    world: Any,
    top: Observation,
    poses: np.ndarray,
    rng: np.random.Generator,
    log: EpisodeLog,
    t: float,
) -> tuple[Target | None, Any, dict[str, Any], float]:
    """The variant's slide: (target or None, the oracle's simulated result or None, the
    decision's facts, the time after any POMDP observations)."""
    cfg, variant = job.cfg, job.condition
    facts: dict[str, Any] = {}
    chosen: Target | None = None
    result = None
    if variant == "oracle":
        chosen, result, tried = _oracle_choice(poses, top, cfg)
        facts = {"slides_simulated": tried}
    else:
        offered = _targets(variant, job, top, rng)
        refused = []
        for target in offered:
            if variant in ("random", "convnet_no_pomdp"):
                chosen = target
                break
            ok, facts, t = run_pomdp(world, target, top, cfg, log, t)
            if ok:
                chosen = target
                break
            refused.append({"piece": target.piece, "probability": target.probability, **facts})
        facts = {**facts, "offered": len(offered), "refused": refused}
    return chosen, result, facts, t


def _slide(
    job: Ch3Job,
    step: int,
    poses: np.ndarray,
    chosen: Target,
    result: Any,
    facts: dict[str, Any],
    steps: list[dict[str, Any]],
    log: EpisodeLog,
    t: float,
) -> tuple[Any, np.ndarray, float]:
    """The chosen slide logged, executed (unless the oracle's simulation is its result) and
    judged, its record appended to `steps`; (its result, the poses after, the time)."""
    from clutterbench.sim.pile import PileWorld, on_board, slide

    cfg = job.cfg
    angle = chosen.angle_rad(cfg.scan.n_directions)
    log.json(
        t,
        "/planner/decision",
        {
            "step": step,
            "action": "slide",
            "piece": chosen.piece,
            "start_xy": list(chosen.start_xy),
            "direction_deg": float(np.degrees(angle)),
            "probability": chosen.probability,
        },
    )
    if result is None:
        result = slide(PileWorld.from_poses(poses, cfg.pile), chosen.piece, angle, cfg.slide)
    t += STEP_S
    after = np.array(result.poses_after, dtype=np.float64)
    after[chosen.piece] = np.nan
    others = [k for k in range(len(poses)) if k != chosen.piece and np.isfinite(poses[k, 0])]
    motion = criteria.box_motion(
        poses, result.poses_after, on_board(result.poses_after, cfg.pile.board_size_m), others
    )
    steps.append(
        {
            "step": step,
            "piece": chosen.piece,
            "direction": chosen.direction,
            "probability": chosen.probability,
            **slide_outcome(bool(result.target_out), bool(result.others_still)),
            "collapse_free": criteria.collapse_free(motion, job.collapse_free),
            "box_motion": motion,
            "moved": list(result.moved),
            "max_displacement_m": float(np.nanmax(result.displacement_m, initial=0.0)),
            "observations": int(facts.get("observations", 0)),
            **{k: v for k, v in facts.items() if k in ("slides_simulated", "offered")},
        }
    )
    log.json(t, "/trial/slide", steps[-1])
    return result, after, t


def _game_record(
    job: Ch3Job, spec: Any, steps: list[dict[str, Any]], end: str, stop: dict[str, Any]
) -> dict[str, Any]:
    """The game's record: its pile, how it ended, and its slides."""
    from clutterbench.sim import benchmark
    from clutterbench.sim.pile import pile_hash

    cfg = job.cfg
    removed = sum(s["success"] for s in steps)
    return {
        "condition": job.condition,
        "game": job.index,
        "seed": job.seed,
        "moved_threshold_m": cfg.slide.moved_threshold_m,
        "collapse_free_params": dataclasses.asdict(job.collapse_free),
        "scene": pile_hash(spec),
        "scene_source": benchmark.source_of(pile_hash(spec)),
        "n_pieces": int(len(spec.poses)),
        "pieces_removed": int(removed),
        "slides": len(steps),
        "end": end,
        "success": removed > 0,
        "strict_success": removed > 0,
        "steps": steps,
        "stop": stop,
    }


def slide_outcome(target_out: bool, others_still: bool) -> dict[str, Any]:
    """A slide's named outcome, with the fields every chapter's step records carry
    (trials/protocol.STEP_FIELDS). A slide always runs to its end: executed, judged, never
    aborted. Chapter 3 has one criterion, the game's (thesis 3.5: the piece off the board,
    no other piece moved beyond yamakuzushi.slide.moved_threshold_m or off the board), so
    `success` and `strict_success` are the same; `collapse_free` (trials.collapse_free's
    drop / tilt, the board as the shelf) is recorded beside it for re-judging."""
    success = target_out and others_still
    return {
        "executed": True,
        "aborted_before_motion": False,
        "aborted_after_motion": False,
        "extracted": target_out,
        "target_out": target_out,
        "others_still": others_still,
        "judged": True,
        "counted": True,
        "strict_counted": True,
        "success": success,
        "strict_success": success,
    }


DEFAULT_COLLAPSE_FREE = CollapseFreeConfig()


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class Ch3Job(EpisodeJob):
    """One ch. 3 game: variant `condition` plays game `index` on the pile of `seed`."""

    cfg: Ch3Config
    """The yamakuzushi configuration (the pile, camera, scan, selection, slide, games)."""
    model: str | None
    """The slide ConvNet's checkpoint (None: no ConvNet variant runs)."""


def ch3_jobs(
    *,
    cfg: Ch3Config,
    seed_of: Callable[[int], int],
    model: str | None,
    collapse_free: CollapseFreeConfig = DEFAULT_COLLAPSE_FREE,
) -> list[Ch3Job]:
    """Every (variant, game) job; game g of every variant plays the pile of seed_of(g)."""
    return [
        Ch3Job(
            collapse_free=collapse_free,
            condition=v,
            index=g,
            seed=seed_of(g),
            cfg=cfg,
            model=model,
            record_images=cfg.games.mcap_images,
        )
        for v in cfg.games.variants
        for g in range(cfg.games.n_games)
    ]


def slide_rows(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per slide: the game's variant, index and seed beside the slide's facts."""
    return [
        {"condition": r["condition"], "game": r["game"], "seed": r["seed"], **s}
        for r in records
        for s in r["steps"]
    ]
