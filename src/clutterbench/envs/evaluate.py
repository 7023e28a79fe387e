"""Evaluate any agent on the planning env: episodes of a stream -> the trials' records and
summary (`clutterbench evaluate-agent MODULE:FACTORY`).

The agent runs through `ClutterShelfPlan-v1` exactly as a trials condition runs a planner:
the same scenes and targets (episode i of the stream), the same episode protocol
(trials.ch6.Extraction), one process with one torch thread (the trials workers' setting), and
the records, summary and MCAP are written by the trials' own writer (harness.write_condition),
both success criteria (`success`: collapse-free; `strict_success`) included, so a row is
comparable with Table 6.3's row on that stream. Those episodes and the trials' outcomes on them
are public, so such a row is on trust; with `fresh` the agent runs episodes of a fresh stream of
the same kind instead, drawn from a seed nobody has seen (fresh_source).
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable
from pathlib import Path
from typing import Any

from clutterbench.errors import ActionError, ClutterbenchError


class AgentError(ClutterbenchError):
    """An agent failed during an episode (its act() or reset() raised, or its action was
    refused): one line naming the agent, the episode and the exception; the exception itself
    is the __cause__ (`clutterbench evaluate-agent --traceback` prints its trace)."""


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def load_factory(ref: str) -> Callable[[Any], Any]:
    """MODULE:FACTORY -> the factory; MODULE is an importable module or a .py file."""
    module_name, sep, attr = ref.rpartition(":")
    if not sep or not module_name or not attr:
        raise ClutterbenchError(f"agent {ref!r}: give MODULE:FACTORY (e.g. my_agent.py:make)")
    if module_name.endswith(".py") or "/" in module_name:
        path = Path(module_name)
        if not path.is_file():
            raise ClutterbenchError(f"agent {ref!r}: no file {path}")
        spec = importlib.util.spec_from_file_location(f"_agent_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
        except Exception as exc:
            raise ClutterbenchError(f"agent {ref!r}: {path} failed to load ({exc})") from None
    else:
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            raise ClutterbenchError(f"agent {ref!r}: cannot import {module_name} ({exc})") from None
    factory = getattr(module, attr, None)
    if not callable(factory):
        raise ClutterbenchError(f"agent {ref!r}: {module_name} has no callable {attr!r}")
    return factory


def run_agent(env: Any, agent: Any, episodes: range, label: str = "episodes") -> list[Any]:
    """Run `agent` on each episode index of `episodes` -> their EpisodeResults, in order.
    An agent that raises, or whose action the env refuses or takes as a no-op
    (info["invalid_action"]), ends the run with an AgentError naming `label` and the
    episode."""
    from clutterbench.progress import progress_bar

    u = env.unwrapped
    policy = agent if callable(agent) else getattr(agent, "act", None)
    if policy is None:
        raise ClutterbenchError("agent: the factory returned neither a callable nor an act(obs)")
    monitor = getattr(agent, "collapse_score", None)
    if monitor is not None:
        u.set_monitor(
            monitor, getattr(agent, "cp_max", float("inf")), getattr(agent, "last_decision", None)
        )
    results = []
    with progress_bar(label, total=len(episodes)) as advance:
        for i in episodes:
            obs, _ = env.reset(seed=i)
            where = f"agent {label}, episode {i}"
            if hasattr(agent, "reset"):
                try:
                    agent.reset(i)
                except Exception as exc:
                    raise AgentError(f"{where}: reset() raised {_one_line(exc)}") from exc
            done = False
            while not done:
                try:
                    action = policy(obs)
                except Exception as exc:
                    raise AgentError(f"{where}: act() raised {_one_line(exc)}") from exc
                try:
                    obs, _, terminated, truncated, info = env.step(action)
                except ActionError as exc:
                    raise AgentError(f"{where}: action refused: {exc}") from exc
                if "invalid_action" in info:
                    why = info["invalid_action"]
                    raise AgentError(f"{where}: invalid action {action!r}: {why}")
                done = terminated or truncated
            results.append(u.episode_result())
            advance(1)
    return results


def evaluate_agent(
    ref: str,
    stream: str,
    episodes: int,
    out_dir: Path,
    name: str | None = None,
    first: int = 0,
    scale: str | None = None,
    record_images: bool = False,
    board: Path | None = None,
    fresh: tuple[int, str] | None = None,
) -> dict[str, Any]:
    """Agent `ref` (MODULE:FACTORY) on episodes first..first+episodes-1 of `stream` ->
    out_dir/<name>/records.jsonl, summary.json and episodes.mcap; returns the summary. With
    `board`: also its leaderboard row, paired with the trials' conditions on the same episodes
    (envs/board.py), written to board/agents/<name>.json and board/leaderboard.md. With
    `fresh` (seed, where it came from): episodes 0..episodes-1 of a fresh stream of the
    stream's kind instead (fresh_source), the row in board/fresh/agent-<name>.json."""
    import gymnasium as gym

    import clutterbench.envs  # noqa: F401  (registers the envs)
    from clutterbench.envs import PLAN_ENV_ID
    from clutterbench.parallel import worker_init
    from clutterbench.trials.core.harness import write_condition

    if episodes < 1 or first < 0:
        raise ClutterbenchError(f"--episodes {episodes} / --first {first}: need >= 1 / >= 0")
    factory = load_factory(ref)
    name = name or ref.rpartition(":")[2]
    worker_init(1)  # one renderer, torch on one thread: the trials workers' setting
    env = gym.make(PLAN_ENV_ID, stream=stream, scale=scale, name=name, record_images=record_images)
    scored_on = fresh_source(env.unwrapped, fresh, episodes) if fresh is not None else None
    agent = factory(env)
    results = run_agent(env, agent, range(first, first + episodes), label=name)
    source = env.unwrapped.source
    about = {
        "condition": name,
        "planner": name,
        "agent": ref,
        "stream": source.name,
        "first_episode": first,
        "scale": source.scale,
    } | ({"scored_on": scored_on} if scored_on else {})
    env.close()
    summary = write_condition(name, results, about, out_dir, out_dir)
    if board is not None:
        from clutterbench.envs.board import agent_card, benchmark_pin, write_agent_row
        from clutterbench.platform_info import cpu_model

        pin = None if scored_on else benchmark_pin(board.parent.parent)
        card = agent_card(
            [r.record for r in results],
            {"kind": "agent", "name": name, "agent": ref, "first_episode": first}
            | {"scale": source.scale, "cpu_model": cpu_model()}
            | ({"scored_on": scored_on} if scored_on else {})
            | ({"benchmark_sha256": pin} if pin else {}),
            board.parent / "trials",
        )
        summary["leaderboard_row"] = str(write_agent_row(card, board))
    return summary


def fresh_source(env: Any, fresh: tuple[int, str], episodes: int) -> dict[str, Any]:
    """Point the planning env at a fresh stream of its stream's kind (the same families, box
    counts and catalogue): named fresh/<stream>, drawn with the fresh stream seed of user seed
    `fresh[0]`, kept apart from every project stream as a fresh test set is
    (data/testset_fresh.py). Returns the row's `scored_on`."""
    import dataclasses

    from clutterbench.config import load_params, project_params_path
    from clutterbench.data.testset_fresh import check_apart, fresh_name, stream_seed

    seed, seed_from = fresh
    src = env.source
    check_apart(load_params(project_params_path()), src.seed, seed, [src.name])
    env.source = dataclasses.replace(src, name=fresh_name(src.name), seed=stream_seed(seed))
    return {
        "set": "fresh",
        "scenes": episodes,
        "seed": seed,
        "seed_from": seed_from,
        "stream_seed": stream_seed(seed),
        "stream": src.name,
    }
