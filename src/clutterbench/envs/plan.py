"""`ClutterShelfPlan-v1`: the thesis' planning-level decision as a gymnasium environment.

    import gymnasium as gym
    import clutterbench.envs  # registers it
    env = gym.make("ClutterShelfPlan-v1")              # stream ch6_3_10
    obs, info = env.reset(seed=17)                      # the pipeline's episode 17
    obs, reward, terminated, truncated, info = env.step((pull, hold))

Observation (what the robot sees, nothing else): `depth_m` (H, W) float32 metres along the
optical axis (0: nothing hit), `instance` (H, W) uint8 (0 background, k + 1 = box k: the
simulator's instance image, as the trials' `perception: instance`), the camera's `K` (3, 3)
and `T_world_from_cam` (4, 4, OpenCV camera frame in the shelf frame), the `target` box
and `blocked` (MAX_BOXES,) int8: the boxes whose last pull aborted (the episode's own
history, as the trials hand it to their planners).

Action: (box to pull, box to hold), MultiDiscrete([MAX_BOXES + 1] * 2); NO_BOX (=
MAX_BOXES) holds nothing, and as the box to pull gives up (the episode ends, "gave_up").
An action naming a box not in the scene, or holding the pulled box, is a no-op: nothing
moves, reward 0, the episode goes on, `info["invalid_action"]` says why (so every action of
the space is valid and `action_space.sample()` works; `clutterbench evaluate-agent` refuses
such an action, one line). The action may also be a dict {"pull": box, "hold": box}
("hold" optional). A malformed action (not two integers of the space, NaN, a string, a dict
with other keys) is refused (ActionError). `info["action_mask"]` masks the visible boxes
(and the target) for `action_space.sample(mask=...)`; the held box must differ from the
pulled one.

Each step is one step of the trials' episode protocol (trials.ch6.Extraction, the object the
trials stage drives): executed by the kinematic executor from the step's canonical start,
the held box released and the scene settled, judged from physics. `info` carries the step
record's named booleans (protocol.STEP_FIELDS), `end` (protocol.EPISODE_ENDS, None while it
goes on) and, once it ended, `episode` (the episode's named outcome: `success`, collapse-free,
and `strict_success`): `info["success"]` is the step's, `info["episode"]["success"]` the
episode's. terminated: the protocol ended the episode; truncated: its attempt cap
(trials.ch6.max_steps). Reward (sparse): 1 on the step that ends a collapse-free success.
`render_mode="rgb_array"`: the observation's depth image as grey (near: bright), boxes tinted.

A policy may also monitor its pulls as Algorithm 1 does: `env.unwrapped.set_monitor(score,
cp_max)` with `score(obs, pull, hold) -> float`, called before every pull increment with
the observation of that moment (the first: the one the decision read); a score above cp_max
stops the pull (an abort, as in the trials). With `set_monitor(..., decision=f)`, `f()`
returns the policy's last planning.extraction.Decision (or None): when it is the action
taken, its own abort threshold (`cp_max`, a least-risk pull's) and its notes
(`trials.protocol.STEP_NOTES`) apply to that step, as in the trials.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from clutterbench.errors import ActionError, ClutterbenchError
from clutterbench.maniskill.tasks import refuse_fork_after_render
from clutterbench.observation import CameraModel, Observation
from clutterbench.planning.ch6.extraction import Decision
from clutterbench.sim import benchmark
from clutterbench.sim.labelling import check_n_objects
from clutterbench.trials.core.harness import EpisodeResult
from clutterbench.trials.core.protocol import STEP_FIELDS, STEP_NOTES, judge_episode
from clutterbench.trials.core.streams import StreamSource
from clutterbench.trials.sources import stream_source

if TYPE_CHECKING:
    from clutterbench.trials.ch6.episodes import Ch6Job

MAX_BOXES = 30
"""Box indices an action can name (SceneStreamConfig allows at most 30 boxes)."""
NO_BOX = MAX_BOXES
"""The action's `hold` for nothing held; as `pull`: give up."""
Monitor = Callable[[dict[str, Any], int, "int | None"], float]


def observation_dict(obs: Observation, target: int, blocked: set[int]) -> dict[str, Any]:
    """The env's observation of a rendered view (trials' Observation)."""
    mask = np.zeros(MAX_BOXES, dtype=np.int8)
    mask[sorted(blocked)] = 1
    return {
        "depth_m": obs.depth_m.copy(),  # fresh arrays each call (a policy may keep them)
        "instance": obs.instance.copy(),
        "K": np.array(obs.camera.K, dtype=np.float64),
        "T_world_from_cam": np.array(obs.camera.T_world_from_cam, dtype=np.float64),
        "target": np.int64(target),
        "blocked": mask,
    }


def as_observation(obs: dict[str, Any]) -> Observation:
    """The planners' Observation of an env observation (the same arrays)."""
    return Observation(
        depth_m=obs["depth_m"],
        instance=obs["instance"],
        camera=CameraModel(K=obs["K"], T_world_from_cam=obs["T_world_from_cam"]),
    )


class _Decider:
    """What the episode protocol asks of whoever decided a step: here nothing (no monitor)."""


class _Monitored:
    """... or a collapse score monitoring the pull (Algorithm 1), read on env observations."""

    def __init__(self, env: ClutterShelfPlanEnv, score: Monitor):
        self.env, self.score = env, score

    def collapse_score(self, obs: Observation, box: int, hold: int | None = None) -> float:
        return float(self.score(self.env._as_dict(obs), box, hold))


class ClutterShelfPlanEnv(gym.Env):
    """Pull which box, hold which (see the module's doc). kwargs: `stream` (a key of
    trials.streams, default ch6_3_10) or `family` / `n_objects` / `catalogue`; `scale` (the
    params' scale profile, default base.scale); `name` (the records' condition and planner
    fields); `record_images` (depth and instance images in the episode's MCAP events)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 1}

    def __init__(
        self,
        stream: str | None = None,
        family: Any = None,
        n_objects: Any = None,
        catalogue: str | None = None,
        scale: str | None = None,
        name: str = "agent",
        record_images: bool = False,
        render_mode: str | None = None,
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ClutterbenchError(
                f"render_mode={render_mode!r}: one of {self.metadata['render_modes']} or None"
            )
        self.render_mode = render_mode
        if n_objects is not None:
            check_n_objects(n_objects)
        self.source: StreamSource = stream_source(stream, family, n_objects, catalogue, scale)
        self.name, self.record_images = name, record_images
        size = self.source.camera.image_size
        far_m = float(self.source.camera.far_m)
        self.observation_space = spaces.Dict(
            {
                "depth_m": spaces.Box(0.0, far_m, (size, size), np.float32),
                "instance": spaces.Box(0, 255, (size, size), np.uint8),
                "K": spaces.Box(0.0, 1e6, (3, 3), np.float64),  # pixels
                "T_world_from_cam": spaces.Box(-1e3, 1e3, (4, 4), np.float64),  # metres
                "target": spaces.Discrete(MAX_BOXES),
                "blocked": spaces.MultiBinary(MAX_BOXES),
            }
        )
        self.action_space = spaces.MultiDiscrete([MAX_BOXES + 1, MAX_BOXES + 1])
        self.monitor: Monitor | None = None
        self.cp_max = np.inf
        self.decision_of: Callable[[], Decision | None] | None = None
        self.episode = None
        self.episode_index: int | None = None
        self._next_episode = 0
        self._obs: dict[str, Any] | None = None
        refuse_fork_after_render("ClutterShelfPlan")  # every reset renders the observation

    # -- the policy's optional pull monitor ----------------------------------------------------
    def set_monitor(
        self,
        score: Monitor | None,
        cp_max: float,
        decision: Callable[[], Decision | None] | None = None,
    ) -> None:
        """Monitor every pull with `score(obs, pull, hold)`; above `cp_max` (or the policy's
        decision's own threshold, `decision`: module doc) it stops."""
        self.monitor, self.cp_max, self.decision_of = score, float(cp_max), decision
        if self.episode is not None:
            self.episode.job = dataclasses.replace(self.episode.job, cp_max=self.cp_max)

    def _decider(self) -> Any:
        return _Decider() if self.monitor is None else _Monitored(self, self.monitor)

    def _as_dict(self, obs: Observation) -> dict[str, Any]:
        ep = self.episode
        if obs is ep.obs and self._obs is not None:
            return self._obs  # the observation the decision read: the very same object
        return observation_dict(obs, ep.target, ep.blocked)

    # -- gymnasium -------------------------------------------------------------------------------
    def job(self, index: int) -> Ch6Job:
        """The episode's job, as trials.ch6.ch6_jobs makes one (no planner of the registry:
        the decisions come from `step`)."""
        from clutterbench.trials.ch6.episodes import Ch6Job

        src = self.source
        return Ch6Job(
            condition=self.name,
            planner=self.name,
            rule=None,
            stream=src.name,
            stream_cfg=src.cfg,
            index=index,
            seed=src.seed,
            physics=src.physics,
            camera=src.camera,
            params=src.trials.ch6,
            collapse_free=src.trials.collapse_free,
            support=None,
            cp_max=self.cp_max,
            model_path=None,
            ch4_model_path=None,
            max_attempts=src.trials.max_attempts,
            record_images=self.record_images,
            executor="kinematic",
            arm=src.trials.arm,
        )

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Episode `seed` (an int >= 0; None: the next one) of the stream; options may name
        another stream (`stream`, or `family` / `n_objects` / `catalogue`)."""
        from clutterbench.trials.ch6.episodes import Extraction

        super().reset(seed=seed)
        options = dict(options or {})
        keys = ("stream", "family", "n_objects", "catalogue")
        unknown = set(options) - set(keys)
        if unknown:
            raise ClutterbenchError(
                f"reset options: unknown {', '.join(sorted(unknown))} (known: {', '.join(keys)})"
            )
        if options.get("n_objects") is not None:
            check_n_objects(options["n_objects"], "reset options n_objects")
        if options:
            self.source = stream_source(*(options.get(k) for k in keys), scale=self.source.scale)
        if seed is None:
            index = self._next_episode
        elif isinstance(seed, int | np.integer) and seed >= 0:
            index = int(seed)
        else:
            raise ClutterbenchError(f"reset(seed={seed!r}): an episode index, an int >= 0")
        self.episode_index, self._next_episode = index, index + 1
        spec = self.source.spec(index)
        self.episode = Extraction(spec, self.job(index))
        self._obs = self._observation()
        info = {"action_mask": self.action_mask(), "episode_index": index}
        return self._obs, info | benchmark.scene_fields(spec)

    def _observation(self) -> dict[str, Any]:
        ep = self.episode
        return observation_dict(ep.obs, ep.target, ep.blocked)

    def action_mask(self) -> tuple[np.ndarray, np.ndarray]:
        """(pull, hold) masks for MultiDiscrete sampling: the visible boxes and the target
        (pull; NO_BOX gives up, never sampled), the visible boxes and NO_BOX (hold)."""
        ep = self.episode
        visible = [k for k in ep.obs.visible_boxes(1) if k not in ep.state.removed]
        pull = np.zeros(MAX_BOXES + 1, dtype=np.int8)
        pull[sorted({*visible, ep.target})] = 1
        hold = np.zeros(MAX_BOXES + 1, dtype=np.int8)
        hold[visible] = 1
        hold[NO_BOX] = 1
        return pull, hold

    def _check(self, action: Any) -> tuple[int, int | None, str | None]:
        """-> (pull, hold or None, why the action is a no-op or None); a malformed action
        raises ActionError."""
        ep = self.episode
        form = f"(box to pull, box to hold or {NO_BOX}), two integers"
        if isinstance(action, dict):
            if "pull" not in action or not set(action) <= {"pull", "hold"}:
                raise ActionError(
                    f"action {action!r}: an action dict has the keys 'pull' (box to pull) and "
                    f"'hold' (box to hold, optional: {NO_BOX} for nothing held)"
                )
            action = (action["pull"], action.get("hold", NO_BOX))
        try:
            a = np.asarray(action, dtype=np.float64) if action is not None else np.array([])
        except (TypeError, ValueError):  # a string, a dict, an object: not numbers
            raise ActionError(
                f"action {action!r} (a {type(action).__name__}): an action is {form}"
            ) from None
        if a.shape != (2,):
            raise ActionError(f"action {action!r}: an action is {form}")
        if np.isnan(a).any():
            raise ActionError("action holds NaN (a policy produced NaN; refused)")
        if not np.array_equal(a, np.round(a)) or a.min() < 0 or a.max() > NO_BOX:
            raise ActionError(f"action {action!r}: box indices are integers 0..{NO_BOX}")
        pull, hold = int(a[0]), int(a[1])
        n = ep.spec.n
        in_scene = [k for k in range(n) if k not in ep.state.removed]
        why = None
        if pull != NO_BOX and pull not in in_scene:
            why = f"pull {pull}: not a box in the scene (boxes {in_scene}; {NO_BOX}: give up)"
        elif hold != NO_BOX and (hold not in in_scene or hold == pull):
            why = (
                f"hold {hold}: not a box in the scene other than the pulled one "
                f"(boxes {in_scene}; {NO_BOX}: hold nothing)"
            )
        return pull, (None if hold == NO_BOX else hold), why

    def render(self) -> np.ndarray | None:
        """render_mode "rgb_array": (H, W, 3) uint8 of the observation (module doc)."""
        if self.render_mode is None or self._obs is None:
            return None
        depth, instance = self._obs["depth_m"], self._obs["instance"]
        hit = depth > 0
        grey = np.zeros(depth.shape, dtype=np.float64)
        if hit.any():
            near, far = float(depth[hit].min()), float(depth[hit].max())
            grey[hit] = 1.0 - 0.75 * (depth[hit] - near) / max(far - near, 1e-6)
        tint = np.array([[1.0, 1.0, 1.0], [1.0, 0.6, 0.6], [0.6, 1.0, 0.6], [0.6, 0.6, 1.0]])
        rgb = grey[..., None] * tint[np.where(instance > 0, 1 + instance % 3, 0)]
        return (255 * rgb).astype(np.uint8)

    def step(self, action: Any):
        ep = self.episode
        if ep is None or ep.done:
            raise ClutterbenchError("ClutterShelfPlan: the episode has ended; call reset()")
        pull, hold, why = self._check(action)
        if why is not None:  # a no-op: nothing moves, the episode goes on
            self._obs = self._observation()
            info = {"action_mask": self.action_mask(), "end": None, "invalid_action": why}
            return self._obs, 0.0, False, False, info
        step: dict[str, Any] | None = None
        decider = self._decider()
        ep.before_decision(decider)
        if pull == NO_BOX:
            ep.give_up()
        else:
            step = ep.step(self._decision(pull, hold), decider)
        self._obs = self._observation()
        info: dict[str, Any] = {"action_mask": self.action_mask(), "end": ep.end}
        if step is not None:
            from clutterbench.trials.ch6.episodes import _rounded

            record = _rounded(step)
            info |= {k: record[k] for k in STEP_FIELDS} | {"step": record}
        reward = 0.0
        if ep.done:
            info["episode"] = judge_episode(ep.steps, ep.end, ep.target)
            reward = float(info["episode"]["success"])
        truncated = ep.end == "max_steps"
        terminated = ep.done and not truncated
        return self._obs, reward, terminated, truncated, info

    def _decision(self, pull: int, hold: int | None) -> Decision:
        """The step's Decision: the action, with the policy's own abort threshold and note
        where its last decision (set_monitor's `decision`) is this action."""
        made = self.decision_of() if self.decision_of is not None else None
        if made is None or (made.pull, made.hold) != (pull, hold):
            return Decision(pull, hold, {"policy": self.name})
        # the decision's notes the trials' step record carries
        # (trials/ch6/episodes.py execute_decision)
        note = {k: made.state[k] for k in STEP_NOTES if k in made.state}
        return Decision(pull, hold, {"policy": self.name} | note, made.cp_max)

    def episode_result(self) -> EpisodeResult:
        """The ended episode's record (the trials' format) and its MCAP events."""
        if self.episode is None or not self.episode.done:
            raise ClutterbenchError("ClutterShelfPlan: no ended episode to record")
        return self.episode.result(self._decider())
