"""Table 6.2 offline: support relations inferred from one depth image, scored against physics."""
