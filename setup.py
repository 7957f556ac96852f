"""Package list for setuptools; everything else about the distribution is in pyproject.toml.

Two source folders install under other names, which pyproject.toml's `packages.find` cannot express:
`cli/` becomes the package `vmax_cli` (a top-level `cli` would collide with any other project's `cli` in
site-packages) and `schemas/` becomes the data package `scenariomax._schemas` (a wheel carries the shard schema
inside `scenariomax`; a checkout reads `schemas/` directly, see scenariomax/schema.py).
"""

from __future__ import annotations

from setuptools import find_packages, setup

RENAMED_SOURCE_DIRS = {"vmax_cli": "cli", "scenariomax._schemas": "schemas"}

setup(
    packages=[*find_packages(include=["scenariomax", "scenariomax.*", "vmax_sim", "vmax_sim.*"]),
              *RENAMED_SOURCE_DIRS],
    package_dir=RENAMED_SOURCE_DIRS,
)
