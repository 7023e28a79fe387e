"""One exception type for user-facing problems (bad params, missing or corrupt data).

Stage scripts catch it at the top and exit non-zero with its one-line message.
"""


class ClutterbenchError(Exception):
    """A problem the user can fix; its message is one line naming the problem."""
