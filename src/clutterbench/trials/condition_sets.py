"""The conditions a run has beyond and short of those params.yaml lists: the sensed rows,
added (trials.sensed for chapter 6, trials.ch4_sensed and trials.ch5_sensed for Tables 4.1 and
5.2), and the opt-in rows of chapter 6, left out unless switched on (trials.opt_in).

Imports no SAPIEN and no torch (trials/config.py imports it).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

Sensing = Literal["ideal", "structured_light", "d415"]
"""A depth sensor preset (sim/sensor.py; ideal: the renderer's exact depth)."""

NOT_RUN = "not run (opt-in: make repro-full)"
"""What a table says in place of an opt-in row's figures when the run left it out."""


SENSED_GROUPS = {
    "conditions": "sensed",
    "ch4_conditions": "ch4_sensed",
    "ch5_conditions": "ch5_sensed",
}
"""A trials condition group -> the key of the sensed rows added to it."""


@dataclasses.dataclass(frozen=True)
class SensedRows:
    """Conditions of one group run again as a robot sees: for each condition named in `of`,
    the condition <name>_<sensing>, the same but for its sensor and, where given, its object
    masks (docs/sensing.md)."""

    sensing: Sensing = "d415"
    """The depth sensor of the sensed conditions (sim/sensor.py)."""
    perception: Literal["instance", "depth"] | None = None
    """Their object masks (the group's `perception`: ch. 6 and ch. 4 conditions take
    instance or depth); null: each keeps its own (the ch. 5 detector reads the sensed depth)."""
    of: tuple[str, ...] = ()
    """The group's conditions run again so (none: no sensed condition)."""
    models: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """A network a condition reads (its `model`) -> the one its sensed twin reads instead: a
    train.models entry trained on the sensor's images (its own `sensing`); none: the same."""

    @staticmethod
    def expand(conditions: Mapping[str, Any], sensed: Mapping[str, Any]) -> dict[str, Any]:
        """Raw conditions with the sensed ones added after them (unknown names are left for
        __post_init__'s one-line error)."""
        sensing = sensed.get("sensing", SensedRows.sensing)
        perception = sensed.get("perception", SensedRows.perception)
        extra = {"sensing": sensing} | ({} if perception is None else {"perception": perception})
        models = sensed.get("models") if isinstance(sensed.get("models"), Mapping) else {}
        out = dict(conditions)
        for name in sensed.get("of") or ():
            if isinstance(cond := conditions.get(name), Mapping):
                swap = {"model": models[cond["model"]]} if cond.get("model") in models else {}
                out.setdefault(f"{name}_{sensing}", {**cond, **extra, **swap})
        return out

    @staticmethod
    def add_to(data: Mapping[str, Any]) -> dict[str, Any]:
        """A raw trials section with each group's sensed conditions added (SENSED_GROUPS)."""
        out = dict(data)
        for group, key in SENSED_GROUPS.items():
            if isinstance(data.get(key), Mapping) and isinstance(data.get(group), Mapping):
                out[group] = SensedRows.expand(data[group], data[key])
        return out

    @staticmethod
    def problem_in(trials: Any) -> str | None:
        """One line when a parsed trials section's sensed rows name a condition their group
        lacks; None when none does."""
        for group, key in SENSED_GROUPS.items():
            if problem := getattr(trials, key).problem(group, getattr(trials, group)):
                return f"{key}.of: {problem}"
        return None

    def table_rows(self, rows: Mapping[str, str]) -> dict[str, str]:
        """A table's rows (row -> condition) and, after them, for each condition run again
        under the sensor, the row '<row>/<sensing>' of its sensed twin."""
        out = dict(rows)
        for row, cond in rows.items():
            if cond in self.of:
                out.setdefault(f"{row}/{self.sensing}", f"{cond}_{self.sensing}")
        return out

    def problem(self, group: str, conditions: Mapping[str, Any]) -> str | None:
        """One line when `of` names no condition of the group (its params key `group`)."""
        unknown = [name for name in self.of if name not in conditions]
        return f"no condition {unknown[0]!r} in trials.{group}" if unknown else None


KEPT_ROLES = {
    "oracle": "a search oracle's row (the other rows are measured against it)",
    "floor": "the random floor's row",
}
"""Planner roles (trials/ch6/planners) whose rows every run has: never opt-in."""


@dataclasses.dataclass(frozen=True)
class OptInRows:
    """Conditions of trials.conditions that the trials stage (and the noise stage's replays)
    leave out unless `run` is true: rows that no headline figure reads, whose cost a default
    run need not pay. `make repro-full` (dvc exp run -S trials.opt_in.run=true) runs them; a
    table row of one left out says NOT_RUN (docs/run-times.md)."""

    run: bool = False
    """Run the opt-in conditions too."""
    conditions: tuple[str, ...] = ()
    """The opt-in conditions (keys of trials.conditions): never an oracle's or the floor's row,
    nor one a thesis row of Table 6.3 reads (`clutterbench check` says so)."""

    @property
    def skipped(self) -> tuple[str, ...]:
        """The conditions this run leaves out: the opt-in ones unless `run`."""
        return () if self.run else self.conditions

    def problem(
        self, conditions: Mapping[str, Any], sensed_of: tuple[str, ...], arm_of: Mapping[str, str]
    ) -> str | None:
        """One line when an opt-in name is no condition, or names one that another row needs
        run (a sensed row's ideal twin, an arm-level row's kinematic one); None when fine."""
        for name in self.conditions:
            if name not in conditions:
                return f"opt_in.conditions: no condition {name!r} in trials.conditions"
            if name in sensed_of:
                return f"opt_in.conditions: {name!r} is in sensed.of (its sensed row needs it)"
            for arm, of in arm_of.items():
                if of == name:
                    return f"opt_in.conditions: {name!r} is repeated by arm_conditions.{arm}"
        return None

    def role_problem(
        self, planner_of: Mapping[str, str], role_of: Callable[[str], str | None]
    ) -> str | None:
        """One line when an opt-in condition (name -> its planner in `planner_of`) is a row
        every run has (KEPT_ROLES, by its planner's declared role); None when none is."""
        for name in self.conditions:
            why = KEPT_ROLES.get(role_of(planner_of[name])) if name in planner_of else None
            if why:
                return f"opt_in.conditions: {name!r} is {why}; it may not be opt-in"
        return None


def _mapping(data: Any, key: str) -> Mapping[str, Any]:
    value = data.get(key) if isinstance(data, Mapping) else None
    return value if isinstance(value, Mapping) else {}


def opt_in_lines(trials: Mapping[str, Any], role_of: Callable[[str], str | None]) -> list[str]:
    """`clutterbench check`'s lines on trials.opt_in of a resolved, unparsed trials section:
    each name that is no condition (with the likeliest meant one), else what OptInRows'
    problem and role_problem say. role_of: a planner's role (None: not registered, a problem
    named apart)."""
    from clutterbench.checks import unknown_name

    names = _mapping(trials, "opt_in").get("conditions")
    if not isinstance(names, list):
        return []  # none, or a bad shape the section's own parse names
    sensed = _mapping(trials, "sensed")
    expanded = SensedRows.expand(_mapping(trials, "conditions"), sensed)
    conditions = {str(k): c for k, c in expanded.items() if isinstance(c, Mapping)}
    key, where = "trials.opt_in.conditions", "trials.conditions"
    out = [line for n in names for line in unknown_name(key, n, conditions, "condition", where)]
    if out:
        return out
    rows = OptInRows(conditions=tuple(str(n) for n in names))
    arms = _mapping(trials, "arm_conditions")
    arm_of = {str(k): str(a.get("of")) for k, a in arms.items() if isinstance(a, Mapping)}
    planner_of = {n: str(c.get("planner")) for n, c in conditions.items()}
    sensed_of = sensed.get("of")
    found = [
        rows.problem(conditions, tuple(sensed_of) if isinstance(sensed_of, list) else (), arm_of),
        rows.role_problem(planner_of, role_of),
    ]
    return [f"trials.{line}" for line in found if line]


def thesis_row_lines(
    opt_in: Sequence[str], rows: Mapping[str, Any], thesis_rows: Sequence[Mapping[str, Any]]
) -> list[str]:
    """A line for each opt-in condition that runs a Table 6.3 row the thesis has (`rows`:
    report.table_6_3, '<method>/<objects>' -> condition; `thesis_rows`: the thesis figures'
    table_6_3 rows), whose figures the README's results at a glance quote."""
    out: dict[str, None] = {}
    for r in (r for r in thesis_rows if isinstance(r, Mapping)):
        row = f"{r.get('method')}/{r.get('n_objects')}"
        if rows.get(row) in opt_in:
            out[
                f"trials.opt_in.conditions: {rows[row]!r} runs Table 6.3's thesis row {row} (the "
                "README's results at a glance quote it); it may not be opt-in"
            ] = None
    return list(out)
