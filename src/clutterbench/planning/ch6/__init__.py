"""Chapter 6's planning: support graphs, collapse prediction graphs, multi-step extraction and
the physics-from-depth planner."""
