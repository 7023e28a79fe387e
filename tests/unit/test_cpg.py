"""The collapse prediction graph and extraction order (thesis 6.2.3, Fig. 6.6, Fig. 6.7)."""

from __future__ import annotations

import networkx as nx
import pytest

from clutterbench.planning.ch6.cpg import (
    BimanualPlan,
    bimanual_plan,
    build_cpg,
    extractable,
    extraction_order,
    next_extractable,
    single_arm_plan,
)
from clutterbench.planning.ch6.support import SupportEdge


def edges(*triples: tuple[int, int, float]) -> list[SupportEdge]:
    return [SupportEdge(a, b, s) for a, b, s in triples]


def levels(graph: nx.DiGraph) -> dict[int, int]:
    return dict(graph.nodes(data="level"))


def test_three_box_stack():
    g = build_cpg(edges((0, 1, 0.9), (1, 2, 0.8)), target=0)
    assert levels(g) == {0: 0, 1: 1, 2: 2}
    assert extraction_order(g, 0) == [2, 1, 0]
    assert extractable(g, 0) == [2]
    assert g.edges[1, 2]["score"] == 0.8


def test_fig_6_6c_keeps_only_the_deepest_parent():
    t, a, b, c = 5, 3, 1, 7  # ids unordered so the order comes from the levels
    g = build_cpg(edges((t, a, 0.9), (t, b, 0.9), (a, b, 0.5), (b, c, 0.9)), target=t)
    assert set(g.edges) == {(t, a), (a, b), (b, c)}  # T -> B pruned: B is level 2 under A
    assert levels(g) == {t: 0, a: 1, b: 2, c: 3}
    assert extraction_order(g, t) == [c, b, a, t]
    assert nx.is_arborescence(g)


def test_two_parents_on_one_level_keep_the_higher_score_then_lower_id():
    g = build_cpg(edges((0, 1, 0.9), (0, 2, 0.9), (1, 3, 0.6), (2, 3, 0.8)), target=0)
    assert set(g.predecessors(3)) == {2}
    tie = build_cpg(edges((0, 2, 0.9), (0, 1, 0.9), (2, 3, 0.7), (1, 3, 0.7)), target=0)
    assert set(tie.predecessors(3)) == {1}


def test_cycle_breaking_drops_the_lowest_score_edge():
    g = build_cpg(edges((0, 1, 0.9), (1, 2, 0.8), (2, 3, 0.7), (3, 1, 0.4)), target=0)
    assert set(g.edges) == {(0, 1), (1, 2), (2, 3)}
    assert levels(g) == {0: 0, 1: 1, 2: 2, 3: 3}
    # When the weakest edge of a cycle leaves the target, the rest is cut off from it.
    g = build_cpg(edges((0, 1, 0.2), (1, 0, 0.9), (1, 2, 0.9)), target=0)
    assert list(g.nodes) == [0] and g.number_of_edges() == 0


def test_boxes_not_reachable_from_the_target_are_left_out():
    g = build_cpg(edges((0, 1, 0.9), (8, 9, 0.9), (8, 0, 0.9), (2, 1, 0.9)), target=0)
    assert sorted(g.nodes) == [0, 1]
    lone = build_cpg([], target=4)
    assert list(lone.nodes) == [4] and levels(lone) == {4: 0}
    assert extractable(lone, 4) == [4]


def test_extractable_order_and_blocked():
    # T supports A and B; A supports C: leaves C (level 2) then B (level 1).
    g = build_cpg(edges((0, 1, 0.9), (0, 2, 0.9), (1, 3, 0.9)), target=0)
    assert extractable(g, 0) == [3, 2]
    assert next_extractable(g, 0) == 3
    assert next_extractable(g, 0, frozenset({3})) == 2
    assert next_extractable(g, 0, frozenset({2, 3})) is None


def test_order_needs_a_tree_with_the_target():
    g = build_cpg(edges((0, 1, 0.9)), target=0)
    with pytest.raises(ValueError, match="target"):
        extraction_order(g, 5)
    not_a_tree = nx.DiGraph([(0, 1), (0, 2), (1, 2)])
    with pytest.raises(ValueError, match="tree"):
        extraction_order(not_a_tree, 0)


def test_bimanual_target_alone_or_with_one_child():
    assert bimanual_plan(build_cpg([], target=0), 0) == BimanualPlan(None, 0, 0)
    g = build_cpg(edges((0, 1, 0.9), (1, 2, 0.9)), target=0)
    # Fig. 6.7 (d): hold the one supported box (its own load stays on it), pull the target.
    assert bimanual_plan(g, 0) == BimanualPlan(hold=1, pull=0, steps_to_target=0)
    assert single_arm_plan(g, 0) == BimanualPlan(hold=None, pull=2, steps_to_target=2)


def test_bimanual_two_children_removes_the_smaller_subtree_first():
    # Target 0 supports 9 (subtree size 1) and 1 (subtree {1, 2, 3}, size 3).
    g = build_cpg(edges((0, 9, 0.9), (0, 1, 0.9), (1, 2, 0.9), (1, 3, 0.9)), target=0)
    assert bimanual_plan(g, 0) == BimanualPlan(hold=None, pull=9, steps_to_target=1)
    assert single_arm_plan(g, 0) == BimanualPlan(hold=None, pull=2, steps_to_target=4)
    # 9 blocked: fall back to the single-arm plan's first free leaf.
    assert bimanual_plan(g, 0, frozenset({9})) == BimanualPlan(None, 2, 4)


def test_bimanual_three_children_keeps_the_largest():
    # Children 5 (size 1), 4 (size 2: 4 -> 6), 1 (size 3: 1 -> 2 -> 3).
    triples = [(0, 5, 0.9), (0, 4, 0.9), (4, 6, 0.9), (0, 1, 0.9), (1, 2, 0.9), (2, 3, 0.9)]
    g = build_cpg(edges(*triples), target=0)
    assert bimanual_plan(g, 0) == BimanualPlan(hold=None, pull=5, steps_to_target=3)
    # 5 blocked: next smallest subtree, its deepest leaf.
    assert bimanual_plan(g, 0, frozenset({5})) == BimanualPlan(None, 6, 3)


def test_plans_raise_when_everything_is_blocked():
    g = build_cpg(edges((0, 1, 0.9)), target=0)
    with pytest.raises(ValueError, match="blocked"):
        single_arm_plan(g, 0, frozenset({1}))
    with pytest.raises(ValueError, match="blocked"):
        bimanual_plan(build_cpg([], target=0), 0, frozenset({0}))


def test_duplicate_edges_keep_the_highest_score_and_self_support_is_rejected():
    for triples in ([(0, 1, 0.8), (0, 1, 0.3)], [(0, 1, 0.3), (0, 1, 0.8)]):
        assert build_cpg(edges(*triples), target=0).edges[0, 1]["score"] == 0.8
    with pytest.raises(ValueError, match="itself"):
        build_cpg(edges((0, 0, 0.9)), target=0)


def test_bimanual_clears_the_held_boxs_load_first_when_asked():
    """The held box is let go after the pull and what it carries falls then; with
    clear_hold_load its subtree goes first, leaves first, then the held pull."""
    g = build_cpg(edges((0, 1, 0.9), (1, 2, 0.9), (2, 3, 0.9)), target=0)
    assert bimanual_plan(g, 0) == BimanualPlan(hold=1, pull=0, steps_to_target=0)  # thesis
    assert bimanual_plan(g, 0, clear_hold_load=True) == BimanualPlan(None, 3, 2)
    # once the load is gone: hold 1, pull the target
    bare = build_cpg(edges((0, 1, 0.9)), target=0)
    assert bimanual_plan(bare, 0, clear_hold_load=True) == BimanualPlan(1, 0, 0)
    # a blocked load leaf: the held pull goes ahead (nothing else to clear first)
    assert bimanual_plan(g, 0, frozenset({3}), clear_hold_load=True) == BimanualPlan(1, 0, 0)
    # two children: the kept child's load is cleared once the others are gone
    g2 = build_cpg(edges((0, 9, 0.9), (0, 1, 0.9), (1, 2, 0.9)), target=0)
    assert bimanual_plan(g2, 0, clear_hold_load=True) == BimanualPlan(None, 9, 1)
