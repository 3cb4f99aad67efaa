"""``wip-bench sweep``: a map of the claim over many randomised episodes, on Ray.

spec.py (the TOML spec) -> runner.py (Ray tasks, one per episode) -> store.py (JSON lines) ->
report.py, plots.py (summary.json, report.md, heatmaps). keys.py says which override keys are
valid, seeding.py where every episode's seed comes from, episode.py is the one call of the
episode runner. Ray is imported only by runner.py (the ``sweep`` extra).
"""
