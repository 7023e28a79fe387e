"""Chapter 6's trials: multi-step and bimanual extraction (Table 6.3), with its oracles,
planners and world models."""
