"""Planning from what a robot sees: support relations, the collapse prediction graph (ch. 6)."""
