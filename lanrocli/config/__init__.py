"""Curricula: the YAML reader with located errors, the schema of a curriculum's sections and the
``--set`` overrides. Light: nothing here loads torch or pybullet."""
