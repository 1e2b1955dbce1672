"""The shipped task files as package data (``sctd_tasks``). ``sctd.task.catalog`` finds a
task here by name (``sctd sim --task pour``); their format is in ``docs/tasks.md``."""
