"""The ch. 4 risk index and the choice of an extraction / support pair (thesis eqs. 4.1, 4.2).

The ch. 4 network maps (depth, extraction mask, support mask) to per-pixel probabilities of
four classes: the extracted object E, the supported object S, the collapsing region C and the
background B (thesis 4.2.2). Candidates are batched through it elsewhere; this module gets
their probability maps, scores each action by the share of the picture predicted to collapse,
and picks the least. Two situations (4.2.3): (a) any pair may be chosen (e.g. to empty a
shelf); (b) the target is given and only its support is chosen.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

CLASSES = ("B", "E", "S", "C")
"""Output channels of the ch. 4 network, in index order (data.labels.PULL_CLASSES: the label
values it was trained on; collapse last)."""
B, E, S, C = range(4)
PIXEL_THRESHOLD = 0.4
"""A pixel belongs to a class's region when its probability is above this (thesis 4.4.1)."""

Pair = tuple[int, int | None]
"""(extract, support) object ids; support None: extract with one arm, nothing held."""


def _check_probs(probs: np.ndarray) -> None:
    assert probs.ndim == 4 and probs.shape[1] == len(CLASSES), "probs must be (A, 4, H, W)"
    assert np.all((probs >= 0) & (probs <= 1)), "probs must be probabilities in [0, 1]"


def risk_index(probs: np.ndarray, threshold: float = PIXEL_THRESHOLD) -> np.ndarray:
    """(A, 4, H, W) class probabilities of A action candidates -> (A,) float64 risk r_c.

    r_c(a) = area(R_C) / area(R_E u R_S u R_C u R_B)           # thesis eq. (4.1)

    R_k holds the pixels whose class-k probability is above `threshold` (0.4 in the thesis).
    With a threshold under 0.5 the regions need not partition the picture: a pixel can be in
    two regions (0.45 E and 0.45 C: it counts once in the union and is collapse) or in none
    (no class above 0.4: undecided, left out of numerator and denominator alike). With no
    region at all the ratio is 0 / 0: +inf, since a prediction that claims nothing is no
    evidence that the action is safe.
    """
    _check_probs(probs)
    regions = probs > threshold
    area_c = regions[:, C].sum(axis=(1, 2)).astype(np.float64)
    area_union = regions.any(axis=1).sum(axis=(1, 2)).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(area_union > 0, area_c / area_union, np.inf)


def risk_from_labels(labels: np.ndarray) -> np.ndarray:
    """(A, H, W) class maps (argmax of the probabilities) -> (A,) float64 r_c: the reading
    of eq. (4.1) in which every pixel is in exactly one region, so the union is the whole
    picture and r_c is the fraction of pixels labelled C."""
    assert labels.ndim == 3 and np.issubdtype(labels.dtype, np.integer), "labels: (A, H, W) int"
    assert np.all((labels >= 0) & (labels < len(CLASSES))), "labels must be class indices 0..3"
    return (labels == C).mean(axis=(1, 2), dtype=np.float64)


@dataclasses.dataclass(frozen=True)
class PairChoice:
    """The action chosen: which object to pull out, which to hold, and its risk r_c."""

    extract: int
    support: int | None
    risk: float


def candidate_pairs(ids: Sequence[int], with_no_support: bool = False) -> list[Pair]:
    """Every ordered (extract, support) pair of two different objects, N (N - 1) for N ids
    (thesis 4.2.3 (1): "all the combinations of two different targets"), grouped by extract in
    the order of `ids`. With `with_no_support`, each extract's group starts with (extract,
    None), so a tie between holding something and holding nothing goes to holding nothing."""
    ids = [int(i) for i in ids]
    if len(set(ids)) != len(ids):
        raise ValueError(f"object ids must be distinct, got {ids}")
    pairs: list[Pair] = []
    for x in ids:
        if with_no_support:
            pairs.append((x, None))
        pairs.extend((x, s) for s in ids if s != x)
    return pairs


def soft_collapse(probs: np.ndarray) -> np.ndarray:
    """(A, 4, H, W) class probabilities -> (A,) the expected share of the picture that
    collapses, mean P(C): the tie-break of eq. (4.2) where r_c ties (e.g. at 0, when no pixel
    of any candidate reaches the region threshold)."""
    _check_probs(probs)
    return probs[:, C].mean(axis=(1, 2), dtype=np.float64)


def _argmin(
    pairs: Sequence[Pair], risks: np.ndarray, tie_break: np.ndarray | None = None
) -> PairChoice:
    """The least risk; among equal risks the least `tie_break`, then the first candidate."""
    order = np.arange(len(risks))
    keys = (order, risks) if tie_break is None else (order, tie_break, risks)
    k = int(np.lexsort(keys)[0])
    return PairChoice(extract=pairs[k][0], support=pairs[k][1], risk=float(risks[k]))


def _check_risks(pairs: Sequence[Pair], risks: Sequence[float] | np.ndarray) -> np.ndarray:
    r = np.asarray(risks, dtype=np.float64)
    if r.shape != (len(pairs),):
        raise ValueError(f"{len(pairs)} candidate pairs but risks of shape {r.shape}")
    if len(pairs) == 0:
        raise ValueError("no candidate pairs to choose from")
    if np.isnan(r).any():
        raise ValueError("risks hold NaN; risk_index gives +inf, not NaN, for no evidence")
    return r


def _check_tie_break(pairs: Sequence[Pair], tie_break: Sequence[float] | np.ndarray | None):
    if tie_break is None:
        return None
    t = np.asarray(tie_break, dtype=np.float64)
    if t.shape != (len(pairs),) or np.isnan(t).any():
        raise ValueError(f"tie_break must be {len(pairs)} numbers, one per candidate pair")
    return t


def choose_safest_pair(
    pairs: Sequence[Pair],
    risks: Sequence[float] | np.ndarray,
    tie_break: Sequence[float] | np.ndarray | None = None,
) -> PairChoice:
    """a = argmin over candidates of r_c(a')                       # thesis eq. (4.2)

    Equal risks are decided by the least `tie_break` (e.g. soft_collapse) where given, then
    by the first candidate in `pairs` order, so a choice is reproducible."""
    return _argmin(pairs, _check_risks(pairs, risks), _check_tie_break(pairs, tie_break))


def choose_support_for_target(
    target: int,
    pairs: Sequence[Pair],
    risks: Sequence[float] | np.ndarray,
    tie_break: Sequence[float] | np.ndarray | None = None,
) -> PairChoice:
    """Thesis 4.2.3 (2): the target is given; eq. (4.2) over the candidates that extract it,
    i.e. the choice of what to hold. Ties as in choose_safest_pair."""
    r = _check_risks(pairs, risks)
    t = _check_tie_break(pairs, tie_break)
    mine = [k for k, (x, _) in enumerate(pairs) if x == target]
    if not mine:
        raise ValueError(f"no candidate pair extracts target {target}")
    return _argmin([pairs[k] for k in mine], r[mine], None if t is None else t[mine])


def random_pair(pairs: Sequence[Pair], rng: np.random.Generator) -> Pair:
    """A candidate drawn uniformly: the random baseline of every trials table."""
    if len(pairs) == 0:
        raise ValueError("no candidate pairs to choose from")
    return pairs[int(rng.integers(len(pairs)))]
