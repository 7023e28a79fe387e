"""Scene families, one per module, and the registry name -> family."""

from __future__ import annotations

from clutterbench.errors import ClutterbenchError
from clutterbench.sim.families.arrangement import Disorganized, Leaning, Organized
from clutterbench.sim.families.base import Placement, SceneFamily
from clutterbench.sim.families.random_drop import RandomDrop
from clutterbench.sim.families.replenish import ReplenishRandom, ReplenishShelved, ReplenishStacked
from clutterbench.sim.families.shelved import Shelved
from clutterbench.sim.families.stacked import Pile, Stacked

FAMILIES: dict[str, SceneFamily] = {
    f.name: f
    for f in (
        Shelved(),
        Stacked(),
        RandomDrop(),
        Organized(),
        Disorganized(),
        Pile(),
        Leaning(),
        ReplenishStacked(),
        ReplenishShelved(),
        ReplenishRandom(),
    )
}


def get_family(name: str) -> SceneFamily:
    if name not in FAMILIES:
        raise ClutterbenchError(f"unknown scene family '{name}' (known: {', '.join(FAMILIES)})")
    return FAMILIES[name]


__all__ = ["FAMILIES", "Placement", "SceneFamily", "get_family"]
