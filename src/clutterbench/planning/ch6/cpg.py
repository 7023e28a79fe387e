"""The collapse prediction graph (CPG) and extraction order (thesis 6.2.3, Alg. 1, Fig. 6.6, 6.7).

A CPG is a tree rooted at the target: an edge a -> b means a supports b (removing a makes b
fall). Node attribute "level" is the hierarchy number of Fig. 6.6 (target 0), edge attribute
"score" the support score the edge was inferred with. Leaves support nothing and are safe to
remove; the target comes out last.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import networkx as nx

from clutterbench.planning.ch6.support import SupportEdge


def _support_digraph(edges: Iterable[SupportEdge], target: int) -> nx.DiGraph:
    """Every support edge (a duplicate pair keeps its highest score) plus the target."""
    graph = nx.DiGraph()
    graph.add_node(target)
    for e in edges:
        if e.supporter == e.supported:
            raise ValueError(f"edges: box {e.supporter} cannot support itself")
        if graph.has_edge(e.supporter, e.supported):
            if graph.edges[e.supporter, e.supported]["score"] >= e.score:
                continue
        graph.add_edge(e.supporter, e.supported, score=float(e.score))
    return graph


def _reachable(graph: nx.DiGraph, target: int) -> nx.DiGraph:
    """The target and everything it supports, directly or not (the rest cannot matter)."""
    nodes = {target} | nx.descendants(graph, target)
    return graph.subgraph(nodes).copy()


def _break_cycles(graph: nx.DiGraph, target: int) -> nx.DiGraph:
    """Drop the lowest-score edge lying on any cycle (ties: smallest (supporter, supported))
    until the graph is acyclic; boxes cut off from the target leave with their edges."""
    while True:
        component = {}
        for i, nodes in enumerate(nx.strongly_connected_components(graph)):
            component.update(dict.fromkeys(nodes, i))
        # An edge lies on a cycle iff both its ends are in one strongly connected component.
        on_cycle = [(u, v) for u, v in graph.edges if component[u] == component[v]]
        if not on_cycle:
            return graph
        u, v = min(on_cycle, key=lambda uv: (graph.edges[uv]["score"], uv))
        graph.remove_edge(u, v)
        graph = _reachable(graph, target)


def _longest_path_levels(dag: nx.DiGraph) -> dict[int, int]:
    """Each node's longest path length from the root (the only node without parents)."""
    level: dict[int, int] = {}
    for node in nx.topological_sort(dag):
        level[node] = max((level[p] + 1 for p in dag.predecessors(node)), default=0)
    return level


def build_cpg(edges: Iterable[SupportEdge], target: int) -> nx.DiGraph:
    """The CPG of `target` (thesis 6.2.3, Fig. 6.6): support edges reachable from the target,
    cycles broken at their weakest edge, levels = longest path from the target, and each node
    kept under one parent only, at the level just above it (Fig. 6.6 (c)), so it is a tree."""
    dag = _break_cycles(_reachable(_support_digraph(edges, target), target), target)
    level = _longest_path_levels(dag)
    tree = nx.DiGraph()
    for node in sorted(dag.nodes):
        tree.add_node(node, level=level[node])
    for node in sorted(dag.nodes):
        # Fig. 6.6 (c): keep the relation to the deepest parent layer, prune the others; a
        # parent at level - 1 always exists, as the longest path arrives through one.
        parents = [p for p in dag.predecessors(node) if level[p] == level[node] - 1]
        if parents:
            parent = min(parents, key=lambda p: (-dag.edges[p, node]["score"], p))
            tree.add_edge(parent, node, score=dag.edges[parent, node]["score"])
    return tree


def _check_cpg(graph: nx.DiGraph, target: int) -> None:
    if target not in graph:
        raise ValueError(f"target: box {target} is not in the graph")
    if len(graph) > 1 and not nx.is_arborescence(graph):
        raise ValueError("graph: a CPG must be a tree rooted at the target (use build_cpg)")


def extraction_order(graph: nx.DiGraph, target: int) -> list[int]:
    """Reverse level-order traversal (thesis 6.2.3): deepest level first, ties by ascending
    box id; the target last."""
    _check_cpg(graph, target)
    others = sorted(
        (n for n in graph.nodes if n != target), key=lambda n: (-graph.nodes[n]["level"], n)
    )
    return [*others, target]


def extractable(graph: nx.DiGraph, target: int) -> list[int]:
    """The leaves (supporting nothing, safe to remove now) in extraction order; only the
    target when it supports nothing."""
    return [n for n in extraction_order(graph, target) if graph.out_degree(n) == 0]


def next_extractable(
    graph: nx.DiGraph, target: int, blocked: frozenset[int] = frozenset()
) -> int | None:
    """The first extractable box not in `blocked` (Alg. 1 line 4: a box whose collapse score
    went over cp_max is blocked); None if every one is."""
    return next((n for n in extractable(graph, target) if n not in blocked), None)


@dataclasses.dataclass(frozen=True)
class BimanualPlan:
    """The next action toward extracting the target."""

    hold: int | None
    """The box to hold while pulling `pull` (None: single-arm)."""
    pull: int
    """The box to pull now."""
    steps_to_target: int
    """How many boxes must still be removed before the target can be pulled (0: pull is it)."""


def _subtree(graph: nx.DiGraph, root: int) -> set[int]:
    return {root} | nx.descendants(graph, root)


def single_arm_plan(
    graph: nx.DiGraph, target: int, blocked: frozenset[int] = frozenset()
) -> BimanualPlan:
    """Single-arm extraction (Alg. 1): pull the next extractable box; every other box of the
    CPG has to go before the target."""
    pull = next_extractable(graph, target, blocked)
    if pull is None:
        raise ValueError(f"blocked: every extractable box of target {target}'s CPG is blocked")
    return BimanualPlan(hold=None, pull=pull, steps_to_target=len(graph) - 1)


def bimanual_plan(
    graph: nx.DiGraph,
    target: int,
    blocked: frozenset[int] = frozenset(),
    clear_hold_load: bool = False,
) -> BimanualPlan:
    """Bimanual extraction (thesis Fig. 6.7).

    With at most one supported child the target is pulled now while the other arm holds that
    child (d). Otherwise the child with the largest subtree stays, to be held, and the other
    children's subtrees are removed first, smallest subtree first, leaves in reverse level
    order (c). When the target itself or every such leaf is blocked, the plan falls back to
    the single-arm plan (any non-blocked leaf; steps_to_target counts every other box).

    `clear_hold_load` (not the thesis): the box to be held is let go after the pull,
    and what it carries falls then, so its own subtree is removed first (its leaves, as any
    other), and the held pull comes after.
    """
    _check_cpg(graph, target)
    children = sorted(graph.successors(target))
    if len(children) <= 1 and target not in blocked:
        hold = children[0] if children else None
        if clear_hold_load and hold is not None:
            load = _subtree(graph, hold) - {hold}
            leaves = [n for n in extractable(graph, target) if n in load and n not in blocked]
            if leaves:
                return BimanualPlan(hold=None, pull=leaves[0], steps_to_target=len(load))
        return BimanualPlan(hold=hold, pull=target, steps_to_target=0)
    if len(children) >= 2:
        subtrees = {c: _subtree(graph, c) for c in children}
        kept = min(children, key=lambda c: (-len(subtrees[c]), c))
        others = sorted((c for c in children if c != kept), key=lambda c: (len(subtrees[c]), c))
        leaves = extractable(graph, target)
        for child in others:
            pull = next((n for n in leaves if n in subtrees[child] and n not in blocked), None)
            if pull is not None:
                steps = sum(len(subtrees[c]) for c in others)
                return BimanualPlan(hold=None, pull=pull, steps_to_target=steps)
    return single_arm_plan(graph, target, blocked)
