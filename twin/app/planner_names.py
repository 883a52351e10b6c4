"""The names of ``twin search``'s planners, importable without the rest of the app (the command
line offers them as choices, and ``twin --help`` must stay fast)."""

PLANNERS = ("information", "detection", "coverage", "random", "survey")
