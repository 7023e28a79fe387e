"""Design choices on dev streams: off-pipeline commands that recheck a choice informed by
trial outcomes on trial streams of their own (`dev.streams` in experiments/params.yaml, seed
streams "trials/dev_*"), never on the streams the report's tables are made from. Not part of
the clutterbench package: run from the repository root (python -m experiments.<name>). No
stage imports this package or reads its params, so a dev run never makes the pipeline stale
(experiments/README.md indexes the rechecks).
"""
