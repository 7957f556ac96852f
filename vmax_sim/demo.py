"""`vmax-sim demo`: synthetic scenarios -> shards -> inspect -> picture -> expert / constant evaluation.

The README's first job, end to end on a laptop CPU in a few minutes: it exercises the converter
pipeline, the shard format, the loader, the simulator, the metrics and the evaluation suite.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

from scenariomax.schema import Sizes

DEMO_POLICIES = ("expert", "constant")
TRAINING_NOTE = "training (vmax-sim train) is not part of this release yet: the demo stops after evaluation"


def _convert(shards: Path, num_scenarios: int, seed: int, workers: int | None, num_objects: int):
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.sources.synthetic import SyntheticSource

    sizes = Sizes(num_objects=num_objects)
    transform, transform_settings = make_transform()
    settings = ConvertSettings(out=shards, workers=workers, sizes=sizes, progress=True, transform=transform,
                               transform_settings=transform_settings)
    return convert(SyntheticSource(num_scenarios=num_scenarios, seed=seed, sizes=sizes), settings)


def run_demo(out: str | Path = "runs/demo", num_scenarios: int = 32, seed: int = 0, workers: int | None = None,
             batch_size: int = 8, num_objects: int = 64, print_fn: Callable[[str], None] = print) -> dict:
    """Runs the demo into `out` (shards/, scenario.png, summary.json) and returns the summary dict."""
    from scenariomax.inspect import format_report, inspect_shards, load_scenario
    from scenariomax.render import render_scenario
    from vmax_sim.data import DataConfig
    from vmax_sim.evaluation import evaluate, format_summary

    if num_scenarios < 1:
        raise ValueError(f"the demo needs at least one scenario, got num_scenarios={num_scenarios}")
    out = Path(out)
    shards = out / "shards"
    if shards.exists():  # a fresh run each time (the converter refuses a finished output without --resume)
        shutil.rmtree(shards)
    out.mkdir(parents=True, exist_ok=True)

    print_fn(f"[1/4] generating {num_scenarios} synthetic scenarios (seed {seed}) into {shards}")
    conversion = _convert(shards, num_scenarios, seed, workers, num_objects)
    print_fn(f"      {conversion.num_scenarios} scenarios written, {conversion.num_failures} failures")

    print_fn("[2/4] inspecting the shards")
    stats = inspect_shards(shards)
    print_fn(format_report(stats))

    picture = out / "scenario.png"
    scenario = load_scenario(shards)
    render_scenario(scenario, picture, title=scenario.scenario_id)
    print_fn(f"[3/4] rendered {scenario.scenario_id} to {picture}")

    print_fn("[4/4] closed-loop evaluation (non-reactive: other road users replay the log)")
    data = DataConfig(path=str(shards), batch_size=min(batch_size, num_scenarios), num_objects=num_objects)
    evaluations = {}
    for policy in DEMO_POLICIES:
        result = evaluate(policy, data)
        evaluations[policy] = result.summary
        print_fn(format_summary(result.summary))
    print_fn(TRAINING_NOTE)

    summary = {
        "out": str(out), "shards": str(shards), "scenario_png": str(picture), "seed": seed,
        "conversion": {"num_scenarios": conversion.num_scenarios, "num_failures": conversion.num_failures},
        "inspect": {"num_records": stats.get("num_records"), "validation": stats.get("validation")},
        "evaluation": evaluations, "training": TRAINING_NOTE,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    print_fn(f"summary written to {out / 'summary.json'}")
    return summary
