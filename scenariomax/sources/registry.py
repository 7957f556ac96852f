"""Maps `--dataset` names to Source classes (imported lazily: each source has its own deps)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from scenariomax.errors import InputError
from scenariomax.schema import Sizes
from scenariomax.sources.base import Source

DATASETS = ("synthetic", "womd", "nuplan", "av2", "scenarionet", "gpudrive")


def make_source(dataset: str, *, src: str | None = None, sizes: Sizes | None = None, num_scenarios: int = 100,
                seed: int = 0, maps: str | None = None, stride_steps: int | None = None,
                sdc_paths: str = "auto", orient_edges: bool = True) -> Source:
    """Builds the Source for a dataset name; raises InputError with a one-line reason. `sdc_paths`
    (WOMD Scenario protos): "auto" (Waymo's own paths when present), "waymo" or "reconstruct". `orient_edges`
    False: WOMD and ScenarioNet maps keep their road edges as written (when the enrichment orients them)."""
    sizes = sizes or Sizes()
    if dataset == "synthetic":
        from scenariomax.sources.synthetic import SyntheticSource

        return SyntheticSource(num_scenarios=num_scenarios, seed=seed, sizes=sizes)
    if dataset == "nuplan":
        from scenariomax.sources.nuplan import NuplanSource

        src, maps = nuplan_locations(src, maps, os.environ)
        return NuplanSource(src=src, maps_root=maps, sizes=sizes, stride_steps=stride_steps)
    if src is None:
        raise InputError(f"--dataset {dataset} needs --src (the raw files or directory)")
    if dataset == "womd":
        from scenariomax.sources.womd import WomdSource

        return WomdSource(src=src, sizes=sizes, sdc_paths=sdc_paths, orient_edges=orient_edges)
    if dataset == "av2":
        from scenariomax.sources.av2 import Av2Source

        return Av2Source(src=src, sizes=sizes)
    if dataset == "scenarionet":
        from scenariomax.sources.scenarionet import ScenarioNetSource

        return ScenarioNetSource(src=src, sizes=sizes, orient_edges=orient_edges)
    if dataset == "gpudrive":
        from scenariomax.sources.gpudrive import GpuDriveSource

        return GpuDriveSource(src=src, sizes=sizes)
    raise InputError(f"unknown dataset {dataset!r}; choose one of {', '.join(DATASETS)}")


def nuplan_locations(src: str | None, maps: str | None, environ: Mapping[str, str]) -> tuple[str, str]:
    """--src and --maps for nuPlan, defaulting to the devkit's variables as its users have them set:
    NUPLAN_DB_FILES (the log databases) else NUPLAN_DATA_ROOT (searched for .db files), and NUPLAN_MAPS_ROOT
    else NUPLAN_DATA_ROOT/maps. Raises one InputError naming every missing location at once."""
    data_root = environ.get("NUPLAN_DATA_ROOT")
    src = src or environ.get("NUPLAN_DB_FILES") or data_root
    if maps is None:
        maps = environ.get("NUPLAN_MAPS_ROOT") or (str(Path(data_root) / "maps") if data_root else None)
    missing = [name for name, value in (("--src (or NUPLAN_DB_FILES / NUPLAN_DATA_ROOT)", src),
                                        ("--maps (or NUPLAN_MAPS_ROOT)", maps)) if not value]
    if missing:
        raise InputError(f"--dataset nuplan needs {' and '.join(missing)}: the log databases and the maps root "
                         "folder, as flags or the nuPlan devkit's environment variables")
    return src, maps
