"""One exception type for user-facing problems (bad params, missing or corrupt data).

Stage scripts catch it at the top and exit non-zero with its one-line message.
"""


class ClutterbenchError(Exception):
    """A problem the user can fix; its message is one line naming the problem."""


class ActionError(ClutterbenchError, ValueError):
    """An action an environment refuses (NaN, a box that is not there): one line naming it;
    a ValueError too, as gymnasium and ManiSkill expect of a bad action."""


class PerceptionError(ClutterbenchError):
    """What one observation could not give (say, a fit of the boxes that no scene can hold):
    recorded in the episode or scene it belongs to and counted in its table, never the end of
    a stage."""


def yaml_problem(exc: Exception) -> str:
    """A YAML parser's error as one line: what it did not find, and where (PyYAML's own
    message spans four lines)."""
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None) or str(exc)
    where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
    return " ".join(f"{problem}{where}".split())
