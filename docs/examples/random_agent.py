"""A random agent for ClutterShelfPlan-v1: pull a random visible box (or the target), hold none.

clutterbench evaluate-agent docs/examples/random_agent.py:make_agent --episodes 20
"""

import numpy as np

from clutterbench.envs import NO_BOX


def make_agent(env):
    rng = np.random.default_rng(0)

    def act(obs):
        visible = np.unique(obs["instance"][obs["instance"] > 0]).astype(int) - 1  # k+1: box k
        return int(rng.choice([*visible, int(obs["target"])])), NO_BOX  # NO_BOX: hold nothing

    return act
