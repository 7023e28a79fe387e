"""The shelf scenes as environments others can plug into (gymnasium ids, all registered when
this package is imported):

- `ClutterShelfExtract-v1`, `ClutterShelfBimanual-v1`: ManiSkill 3 tasks, one or two Pandas
  (maniskill/tasks.py); joint-level control.
- `ClutterShelfPlan-v1`: the thesis' planning-level decision (envs/plan.py): observe, then
  choose the box to pull and the box to hold; each step executed and judged under the
  trials' episode protocol.

With no arguments every env draws its scenes from the stream ch6_3_10: `reset(seed=i)` is
the pipeline's episode i (scene and target). `clutterbench evaluate-agent` runs a policy
through the planning env and writes records like the trials stage (envs/evaluate.py).
Every id's observation, action, action mask, info, episode end and vectorised use:
docs/environments.md.
"""

from __future__ import annotations

import gymnasium as gym

from clutterbench.maniskill import tasks  # registers the ManiSkill tasks
from clutterbench.trials.sources import stream_source

# The ManiSkill tasks draw a spec-less env's scenes from the pipeline's streams: plugged in
# here, above the trials, so that the arm level names nothing of them.
tasks.set_default_scene_source(stream_source)

PLAN_ENV_ID = "ClutterShelfPlan-v1"
ENV_IDS = ("ClutterShelfExtract-v1", "ClutterShelfBimanual-v1", PLAN_ENV_ID)
"""Every environment this project registers (the contract tests parametrize over them)."""

if PLAN_ENV_ID not in gym.registry:
    gym.register(PLAN_ENV_ID, entry_point="clutterbench.envs.plan:ClutterShelfPlanEnv")

from clutterbench.envs.plan import NO_BOX  # noqa: E402

__all__ = ["ENV_IDS", "NO_BOX", "PLAN_ENV_ID"]
