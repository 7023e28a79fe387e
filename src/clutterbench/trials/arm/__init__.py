"""Arm-level trials: ch. 4 and ch. 6 steps executed by ManiSkill's Pandas (Table arm)."""
