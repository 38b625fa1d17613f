"""Many runs of a curriculum at once (seeds, settings and grids of them) on Ray, and their results aggregated
over runs with bootstrap intervals. Only :mod:`lanrocli.sweep.execute` imports Ray."""
