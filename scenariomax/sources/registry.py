"""Maps `--dataset` names to Source classes (imported lazily: each source has its own deps)."""

from __future__ import annotations

from scenariomax.schema import Sizes
from scenariomax.sources.base import InputError, Source

DATASETS = ("synthetic", "womd", "nuplan", "av2", "scenarionet", "gpudrive")


def make_source(dataset: str, *, src: str | None = None, sizes: Sizes | None = None, num_scenarios: int = 100,
                seed: int = 0, maps: str | None = None, stride_steps: int | None = None) -> Source:
    """Builds the Source for a dataset name; raises InputError with a one-line reason."""
    sizes = sizes or Sizes()
    if dataset == "synthetic":
        from scenariomax.sources.synthetic import SyntheticSource

        return SyntheticSource(num_scenarios=num_scenarios, seed=seed, sizes=sizes)
    if src is None:
        raise InputError(f"--dataset {dataset} needs --src (the raw files or directory)")
    if dataset == "womd":
        from scenariomax.sources.womd import WomdSource

        return WomdSource(src=src, sizes=sizes)
    if dataset == "av2":
        from scenariomax.sources.av2 import Av2Source

        return Av2Source(src=src, sizes=sizes)
    if dataset == "scenarionet":
        from scenariomax.sources.scenarionet import ScenarioNetSource

        return ScenarioNetSource(src=src, sizes=sizes)
    if dataset == "gpudrive":
        from scenariomax.sources.gpudrive import GpuDriveSource

        return GpuDriveSource(src=src, sizes=sizes)
    if dataset == "nuplan":
        from scenariomax.sources.nuplan import NuplanSource

        if maps is None:
            raise InputError("--dataset nuplan needs --maps (the nuPlan maps root folder)")
        return NuplanSource(src=src, maps_root=maps, sizes=sizes, stride_steps=stride_steps)
    raise InputError(f"unknown dataset {dataset!r}; choose one of {', '.join(DATASETS)}")
