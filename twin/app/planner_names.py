"""Names the command line offers as choices, importable without the rest of the app (``twin
--help`` must stay fast): ``twin search``'s planners and the factors a batch may vary."""

PLANNERS = ("information", "detection", "coverage", "random", "survey")

# twin batch-survey --vary: the targets' places, the lights, the detector's threshold, and
# (with the twin's realistic camera) each run's camera noise
BATCH_FACTORS = ("target", "lighting", "threshold", "camera")
