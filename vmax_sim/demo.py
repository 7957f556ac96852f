"""`vmax-sim demo`: synthetic scenarios -> shards -> inspect -> a short training run -> evaluation table
-> learning curve and a picture of a trained rollout.

The README's first job, end to end on a laptop CPU in a few minutes: it exercises the converter
pipeline, the shard format, the loader, the simulator, the learning stack (environment, encoder,
learner, replay buffer, checkpoints, logs) and the evaluation suite. Training and evaluation use
disjoint synthetic splits (seed and seed + 1).
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

from scenariomax import Sizes

DEMO_BASELINES = ("expert", "constant")
# Behaviour cloning with the per-group MLP encoder learns to drive in minutes on two CPU cores;
# `vmax-sim train` runs the other algorithms and encoders.
DEMO_PRESET = "bc-mlp-navigation"
EVALUATIONS = 6  # held-out evaluations along the learning curve (the last one at the end)
TRAINED_NAME = "trained BC"  # the trained policy's column and legend entry


def _convert(shards: Path, num_scenarios: int, seed: int, workers: int | None, num_objects: int):
    from scenariomax import ConvertSettings, SyntheticSource, convert, make_transform

    sizes = Sizes(num_objects=num_objects)
    transform, transform_settings = make_transform()
    settings = ConvertSettings(out=shards, workers=workers, sizes=sizes, progress=True, transform=transform,
                               transform_settings=transform_settings)
    return convert(SyntheticSource(num_scenarios=num_scenarios, seed=seed, sizes=sizes), settings)


def _fresh(folder: Path) -> None:
    if folder.exists():  # a fresh run each time (the converter refuses a finished output without --resume)
        shutil.rmtree(folder)


def comparison_markdown(runs, title: str, context: str) -> str:
    """`vmax-sim evaluate`'s comparison table (same rows, names and % values) under a title and a line saying
    what was trained on what and evaluated where."""
    from vmax_sim.evaluation.report import format_markdown

    return f"# {title}\n\n{context}\n\n{format_markdown(runs)}\n"


def redraw_learning_curve(run_dir: Path, title: str, baselines: dict[str, dict]) -> Path:
    """The run's learning curve again, with the baselines' held-out scores as reference lines (training drew it
    before they were evaluated)."""
    from vmax_sim.training.logger import RunLogger
    from vmax_sim.training.plots import plot_learning_curve

    references = {}
    for name, summary in baselines.items():
        metrics = summary.get("metrics", {})
        rates = {k: metrics[k] for k in ("overlap", "offroad", "red_light") if metrics.get(k) is not None}
        references[name] = {"accuracy": summary["accuracy"], "vmax_score": summary["vmax_score"], **rates}
    evaluations = RunLogger(run_dir, tensorboard=False, file_name="eval.csv").rows
    training = RunLogger(run_dir, tensorboard=False, file_name="metrics.csv").rows
    return plot_learning_curve(run_dir / "learning_curve.png", evaluations, training, title=title,
                               baselines=references)


def run_demo(out: str | Path = "runs/demo", num_scenarios: int = 160, num_eval_scenarios: int = 32, seed: int = 0,
             workers: int | None = None, train_steps: int = 24_000, num_objects: int = 64,
             print_fn: Callable[[str], None] = print, progress: bool = True, overrides: Sequence[str] = ()) -> dict:
    """Runs the demo into `out` and returns the summary dict (also written to out/summary.json).

    out/shards, out/eval_shards: the training and held-out synthetic splits; out/scenario.png;
    out/run: the training run (config, checkpoints, metrics.csv, TensorBoard, learning_curve.png);
    out/comparison.md; out/rollout.png: expert and trained policy on one held-out scenario.
    overrides: extra `section.field=value` settings of the training run (see `vmax-sim train`).
    """
    import dataclasses

    import jax

    from scenariomax import format_report, inspect_shards, load_scenario, read_shards, render_scenario
    from vmax_sim.data import DataConfig, scenarios_to_batch
    from vmax_sim.evaluation import evaluate, format_summary
    from vmax_sim.evaluation.report import PolicyRun, compare_policies
    from vmax_sim.evaluation.rollout import make_rollout_fn
    from vmax_sim.metrics import MetricsConfig
    from vmax_sim.training import apply_overrides, preset_config, train
    from vmax_sim.training.run import components
    from vmax_sim.training.run_policy import load_trained_policy
    from vmax_sim.visualization import render_rollouts, rollout_paths

    if num_scenarios < 1 or num_eval_scenarios < 1:
        raise ValueError("the demo needs at least one training and one evaluation scenario")
    out = Path(out)
    shards, eval_shards, run_dir = out / "shards", out / "eval_shards", out / "run"
    for folder in (shards, eval_shards, run_dir):
        _fresh(folder)
    out.mkdir(parents=True, exist_ok=True)

    print_fn(f"[1/5] generating {num_scenarios} training and {num_eval_scenarios} held-out synthetic scenarios "
             f"(seeds {seed}, {seed + 1})")
    conversion = _convert(shards, num_scenarios, seed, workers, num_objects)
    _convert(eval_shards, num_eval_scenarios, seed + 1, workers, num_objects)
    print_fn(f"      {conversion.num_scenarios} scenarios written, {conversion.num_failures} failures")

    print_fn("[2/5] inspecting the training shards")
    stats = inspect_shards(shards)
    print_fn(format_report(stats))
    picture = out / "scenario.png"
    scenario = load_scenario(shards)
    render_scenario(scenario, picture, title=scenario.scenario_id)
    print_fn(f"      rendered {scenario.scenario_id} to {picture}")

    print_fn(f"[3/5] training {DEMO_PRESET} for {train_steps:,} env steps (run directory {run_dir})")
    config = apply_overrides(preset_config(DEMO_PRESET), [
        f"data.train={shards}", f"data.eval={eval_shards}", f"data.num_objects={num_objects}",
        f"train.total_env_steps={train_steps}", f"train.eval_every={max(train_steps // EVALUATIONS, 1)}",
        f"train.eval_scenarios={num_eval_scenarios}", f"train.eval_batch_size={min(16, num_eval_scenarios)}",
        f"train.pool_size={min(32, num_scenarios)}", f"train.pool_refresh={min(4, num_scenarios)}",
        f"train.checkpoint_every={max(train_steps // 2, 1)}", f"train.seed={seed}", *overrides])
    result = train(config, run_dir, progress=progress, print_fn=print_fn)
    print_fn(f"      {result.env_steps:,} env steps in {result.wall_s / 60:.1f} min "
             f"({result.env_steps_per_s:,.0f} env steps/s); learning curve: {run_dir / 'learning_curve.png'}")

    print_fn("[4/5] closed-loop evaluation on the held-out split (non-reactive: others replay the log)")
    runs = compare_policies(list(DEMO_BASELINES), str(eval_shards), batch_size=min(16, num_eval_scenarios),
                            num_objects=num_objects, progress=False, print_fn=print_fn)
    data = DataConfig(path=str(eval_shards), batch_size=min(16, num_eval_scenarios), num_objects=num_objects)
    loaded = load_trained_policy(run_dir)
    env_config = components(loaded.config)[0].env_config
    trained = evaluate(loaded.policy, data, env_config=env_config, obs_config=loaded.config.obs,
                       policy_params=loaded.params)
    runs.append(PolicyRun(TRAINED_NAME, trained, math.nan, 0))
    evaluations = {run.name: run.result.summary for run in runs}
    for summary in evaluations.values():
        print_fn(format_summary(summary))
    context = (f"{DEMO_PRESET} (behaviour cloning with DART noise {config.algo_config.behaviour_noise:g}, MLP "
               f"encoder) trained for {result.env_steps:,} env steps on {num_scenarios} synthetic scenarios "
               f"(seed {seed}); evaluated closed-loop on {num_eval_scenarios} held-out synthetic scenarios "
               f"(seed {seed + 1}), non-reactive (the other agents replay the log), with the expert (log replay) "
               f"and constant velocity beside it.")
    table = comparison_markdown(runs, "V-Max demo: held-out evaluation", context)
    (out / "comparison.md").write_text(table)
    print_fn(table)
    curve_title = (f"BC (MLP encoder), {num_scenarios} synthetic training scenarios -> {num_eval_scenarios} "
                   f"held-out")
    redraw_learning_curve(run_dir, curve_title, {"constant velocity": evaluations["constant"]})

    print_fn("[5/5] drawing the trained policy's rollout beside the expert's")
    first = next(iter(read_shards(eval_shards)))
    one = DataConfig(path=str(eval_shards), batch_size=1, num_objects=num_objects)
    batch = scenarios_to_batch([first], one)
    keys = jax.random.split(jax.random.PRNGKey(seed), 1)
    from vmax_sim.evaluation.evaluate import _environment, _named_policy

    expert_env = _environment(dataclasses.replace(env_config, normalize_actions=False), MetricsConfig())
    expert_fn = make_rollout_fn(expert_env, _named_policy("expert", expert_env), MetricsConfig(), loaded.config.obs)
    trained_fn = make_rollout_fn(_environment(env_config, MetricsConfig()), loaded.policy, MetricsConfig(),
                                 loaded.config.obs)
    paths = {"expert (log replay)": rollout_paths(expert_fn(batch, keys, None)),
             TRAINED_NAME: rollout_paths(trained_fn(batch, keys, loaded.params))}
    rollout_png = render_rollouts(first, paths, out / "rollout.png",
                                  title=f"{first.scenario_id} (held-out): expert vs {TRAINED_NAME}, closed loop, "
                                        f"non-reactive")
    print_fn(f"      {rollout_png}")

    summary = {
        "out": str(out), "shards": str(shards), "eval_shards": str(eval_shards), "scenario_png": str(picture),
        "seed": seed, "conversion": {"num_scenarios": conversion.num_scenarios,
                                     "num_failures": conversion.num_failures},
        "inspect": {"num_records": stats.get("num_records"), "validation": stats.get("validation")},
        "training": {"run_dir": str(run_dir), "preset": DEMO_PRESET, "env_steps": result.env_steps,
                     "wall_s": result.wall_s, "env_steps_per_s": result.env_steps_per_s,
                     "learning_curve_png": str(run_dir / "learning_curve.png")},
        "evaluation": evaluations, "comparison_md": str(out / "comparison.md"), "rollout_png": str(rollout_png),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    print_fn(f"summary written to {out / 'summary.json'}")
    return summary
