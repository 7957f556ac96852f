"""`vmax-sim`: thin click app (parse, build a config, call one library function)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from scenariomax.sources.base import InputError


def _fail(message: str) -> None:
    click.echo(f"error: {message}", err=True)
    sys.exit(2)


def _int_list(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise click.BadParameter(f"expected comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise click.BadParameter(f"expected positive integers, got {text!r}")
    return values


@click.group()
def main() -> None:
    """V-Max simulator: benchmark, evaluate policies, run the demo."""


@main.command()
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON.")
@click.option("--batch-sizes", default="1,32,256", show_default=True, help="Comma-separated batch sizes.")
@click.option("--steps", type=click.IntRange(1), default=80, show_default=True, help="Steps per timed rollout.")
@click.option("--quick", is_flag=True, help="Small run: batch 1 and 8, 20 steps, roadgraph 5k and 30k.")
@click.option("--env", "env_kind", type=click.Choice(["real", "minimal", "both"]), default="real", show_default=True,
              help="Time the real Environment.step, the minimal array step, or both.")
def bench(as_json, batch_sizes, steps, quick, env_kind):
    """Scene-steps per second of the simulator step (env, +observation, +metrics)."""
    from vmax_sim.bench import run_bench

    sizes = _int_list(batch_sizes)
    kwargs = {"batch_sizes": sizes, "steps": steps, "json": as_json, "env_kinds": _env_kinds(env_kind)}
    if quick:
        kwargs.update(batch_sizes=(1, 8), steps=min(steps, 20), roadgraph_sizes=(5000, 30000))
    run_bench(**kwargs)


def _env_kinds(choice: str) -> tuple[str, ...]:
    return ("real", "minimal") if choice == "both" else (choice,)


@main.command()
@click.option("--policy", type=click.Choice(["expert", "constant"]), required=True)
@click.option("--data", required=True, help="Shard directory, file or glob.")
@click.option("--mode", default="non_reactive", show_default=True, help="Evaluation mode (non_reactive).")
@click.option("--batch-size", type=click.IntRange(1), default=8, show_default=True)
@click.option("--num-scenarios", type=click.IntRange(1), default=None, help="Evaluate only the first N.")
@click.option("--num-objects", type=click.IntRange(1), default=64, show_default=True, help="Object slots loaded.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--out", type=click.Path(dir_okay=False), default=None, help="Also write the summary JSON here.")
def evaluate(policy, data, mode, batch_size, num_scenarios, num_objects, as_json, out):
    """Closed-loop evaluation: accuracy, nuPlan and V-Max scores, mean of every metric."""
    from vmax_sim.data import DataConfig
    from vmax_sim.evaluation import evaluate as run_evaluation
    from vmax_sim.evaluation import format_summary

    config = DataConfig(path=data, batch_size=batch_size, num_objects=num_objects)
    try:
        result = run_evaluation(policy, config, mode=mode, num_scenarios=num_scenarios)
    except (InputError, ValueError, OSError) as error:
        _fail(str(error).splitlines()[0] if str(error) else type(error).__name__)
    text = json.dumps(result.summary, indent=2)
    click.echo(text if as_json else format_summary(result.summary))
    if out:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(text)


@main.command()
@click.option("--out", default="runs/demo", show_default=True, type=click.Path(file_okay=False))
@click.option("--num-scenarios", type=click.IntRange(1), default=32, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--workers", type=click.IntRange(1), default=None, help="Conversion workers (default: one per core).")
def demo(out, num_scenarios, seed, workers):
    """Generate synthetic scenarios, inspect and render them, evaluate the expert and a constant policy."""
    from vmax_sim.demo import run_demo

    try:
        run_demo(out, num_scenarios=num_scenarios, seed=seed, workers=workers, print_fn=click.echo)
    except (InputError, ValueError, OSError) as error:
        _fail(str(error).splitlines()[0] if str(error) else type(error).__name__)


if __name__ == "__main__":
    main()
