"""The enrichment step as the pipeline's picklable per-scenario transform."""

from __future__ import annotations

import dataclasses
import functools


def make_transform(enabled: bool = True, num_paths: int = 10, points_per_path: int = 300):
    """Returns (transform or None, settings recorded in the manifest)."""
    if not enabled:
        return None, {"enrich": False}
    from scenariomax.enrich import EnrichSettings, enrich_scenario

    settings = EnrichSettings(num_paths=num_paths, points_per_path=points_per_path)
    return functools.partial(enrich_scenario, settings=settings), {"enrich": dataclasses.asdict(settings)}
