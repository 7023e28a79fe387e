"""Design choices on dev streams: off-pipeline commands that recheck a choice informed by
trial outcomes on trial streams of their own (params `dev.streams`, seed streams
"trials/dev_*"), never on the streams the report's tables are made from. No stage imports
this package, so a dev run never makes the pipeline stale.
"""
