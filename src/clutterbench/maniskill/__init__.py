"""The arm level: ManiSkill 3 tasks built from scene specs (`import clutterbench.maniskill.tasks`
registers ClutterShelfExtract-v1 and ClutterShelfBimanual-v1, as `import mani_skill.envs`
registers ManiSkill's own), the arm-level executor of the trials (`executor.py`), its motion
planning (`motion.py`) and its setup (`config.py`). Importing this package loads nothing heavy:
the trials' params read `config.ArmConfig` without ManiSkill or SAPIEN."""
