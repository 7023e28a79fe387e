"""Per-box outcomes of a pull from one depth image, for three stages: the box head (training
and scoring it), the pull-consequence test set and its scorer, and Table 6.2 (support relations
inferred from one depth image, scored against physics)."""
