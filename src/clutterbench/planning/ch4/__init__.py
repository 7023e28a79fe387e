"""Chapter 4's planning: the risk index and the pull-with-support planner."""
