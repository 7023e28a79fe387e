"""The trials' shared core: the episode jobs' base classes, the harness (jobs -> workers ->
records), the episode protocol and judge, the statistics, the scene streams and the executors
every chapter's trials use."""
