"""`vmax-sim`: thin click app (parse, build a config, call one library function)."""

from __future__ import annotations

import dataclasses
import functools
import json
import sys
from pathlib import Path

import click

from scenariomax.errors import InputError, one_line

VIEW_DEFAULT = "rollouts.html"  # `vmax-sim evaluate --view` with no file name


def _fail(message: str) -> None:
    message = message if len(message) <= 400 else message[:400] + " ..."
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


# What `pip install 'vmax[sim]'` adds (top-level import names); the base install is scenariomax alone.
SIM_EXTRA_MODULES = frozenset({"jax", "jaxlib", "flax", "optax", "orbax", "tensorboardX", "PIL"})


class _NeedsSimExtra(click.Group):
    """Without the `sim` extra a command ends in one line saying what to install, not in an ImportError traceback."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except ModuleNotFoundError as error:
            missing = (error.name or "").split(".")[0]
            if missing not in SIM_EXTRA_MODULES:
                raise
            _fail(f"vmax-sim needs the simulator extra ({missing} is not installed): pip install 'vmax[sim]'")


@click.group(cls=_NeedsSimExtra)
@click.version_option(package_name="vmax", prog_name="vmax-sim")  # the installed metadata: no jax import
def main() -> None:
    """V-Max simulator: train and evaluate policies, benchmark, run the demo.

    Caches (synthetic training splits, map indices) live under $VMAX_CACHE_DIR, default ~/.cache/vmax_sim:
    see `vmax-sim cache info`."""


@main.command()
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON.")
@click.option("--batch-sizes", default="1,32,256,1024,4096", show_default=True,
              help="Comma-separated batch sizes. From 1024 on, each configuration gets 1 warm-up and 3 timed runs "
                   "(seconds each on a CPU); a batch whose states do not fit in free memory is skipped with a note.")
@click.option("--steps", type=click.IntRange(1), default=80, show_default=True, help="Steps per timed rollout.")
@click.option("--quick", is_flag=True, help="Small run: batch 1 and 8, 20 steps, roadgraph 5k and 30k.")
@click.option("--env", "env_kind", type=click.Choice(["real", "minimal", "both"]), default="real", show_default=True,
              help="Time the real Environment.step, the minimal array step, or both.")
@click.option("--compare-waymax", metavar="PYTHON", default=None,
              help="Also time Waymax's physics step on the same scenes with this Python interpreter (one that has "
                   "Waymax installed, e.g. ~/waymax-venv/bin/python) and print the ratios ours / Waymax.")
def bench(as_json, batch_sizes, steps, quick, env_kind, compare_waymax):
    """Scene-steps per second of the simulator step (env, +observation, +metrics) and memory per scene."""
    from vmax_sim.bench import run_bench

    sizes = _int_list(batch_sizes)
    kwargs = {"batch_sizes": sizes, "steps": steps, "json": as_json, "env_kinds": _env_kinds(env_kind),
              "compare_waymax": compare_waymax}
    if quick:
        kwargs.update(batch_sizes=(1, 8), steps=min(steps, 20), roadgraph_sizes=(5000, 30000))
    try:
        run_bench(**kwargs)
    except (ValueError, OSError) as error:
        _fail(one_line(error))


def _run_evaluator(brake_guard: tuple[float, bool] | None):
    """evaluate_run driving with --brake-guard's guard (None: each run's own)."""
    from vmax_sim.training.run_policy import evaluate_run

    if brake_guard is None:
        return evaluate_run
    return functools.partial(evaluate_run, brake_guard_ttc=brake_guard[0], brake_guard_hold=brake_guard[1])


def _env_kinds(choice: str) -> tuple[str, ...]:
    return ("real", "minimal") if choice == "both" else (choice,)


def _brake_guard_option(ctx, param, value: str) -> tuple[float, bool] | None:
    """--brake-guard: "run" -> None (the run's own setting), "off" -> (0.0, False), else seconds in
    train.brake_guard_ttc's range, "+hold" after them for train.brake_guard_hold -> (seconds, hold)."""
    from vmax_sim.training.config import BRAKE_GUARD_MAX_TTC_S

    if value == "run":
        return None
    if value == "off":
        return 0.0, False
    number, hold = (value[:-len("+hold")], True) if value.endswith("+hold") else (value, False)
    try:
        seconds = float(number)
    except ValueError:
        seconds = float("nan")
    if not 0.0 < seconds <= BRAKE_GUARD_MAX_TTC_S and not (seconds == 0.0 and not hold):
        raise click.BadParameter(f"expected run, off, or seconds above 0 up to {BRAKE_GUARD_MAX_TTC_S:g} with an "
                                 f"optional +hold (2+hold), got {value!r}")
    return seconds, hold


def _check_options(fn):
    """--deep / --skip-checks of the commands that read shards for a long time (vmax_sim/data/precheck.py)."""
    fn = click.option("--skip-checks", is_flag=True,
                      help="Start without first reading every record's framing and CRC (bad values still stop the "
                           "run when read).")(fn)
    return click.option("--deep", is_flag=True,
                        help="Before starting, also check every record's values against plausible physical ranges "
                             "(as `scenariomax validate --deep`; ~2 ms a record).")(fn)


def _check_data(specs, deep: bool, skip: bool, quiet: bool, share: tuple[int, int] = (0, 1)) -> None:
    """The shards named by `specs` checked up front (framing and CRC; `deep`: plausibility); InputError on the
    first bad record, naming its file and index. share: (process index, process count) of a multi-process run."""
    if skip:
        return
    from vmax_sim.data.precheck import check_shards, shard_paths

    paths = shard_paths(specs)
    if paths:
        check_shards(paths, deep=deep, progress=not quiet, share=share)


@main.command(context_settings={"ignore_unknown_options": False})
@click.option("--preset", default="bc-dagger", show_default=True,  # = training.config.DEFAULT_PRESET (a test checks)
              help="Words joined by dashes: algorithm (sac, ppo, bc, bc_sac), encoder (none, mlp, lq, lqh, mtr, "
                   "wayformer), reward (safety, navigation, behavior), 'paper' for the paper's hyper-parameters, "
                   "'selfplay' (ppo-selfplay: one policy drives the SDC and every controllable agent), 'dagger' "
                   "(bc-dagger, the default: behaviour cloning taught by PDM-Closed with DAgger, the recipe that "
                   "learnt best in an hour on 2 CPU cores, its replay keeps its 500k steps: 2.4 GB; docs/learning.md); "
                   "both: bc-dagger-selfplay (that learner over every agent, taught by IDM; ~5 GB replay).")
@click.option("--data", default=None, help="Training shards (default: the embedded synthetic split).")
@click.option("--eval-data", default=None, help="Held-out shards for evaluation (default: synthetic, disjoint seeds).")
@click.option("--out", default=None, type=click.Path(file_okay=False),
              help="Run directory (default: runs/<preset>-<time>).")
@click.option("--resume", "resume_dir", default=None, type=click.Path(file_okay=False),
              help="Continue this run directory from its last checkpoint (overrides: only train.total_env_steps, "
                   "train.eval_every, train.checkpoint_every, train.keep_checkpoints, train.max_wall_minutes, "
                   "e.g. to extend a run). Ctrl-C or SIGTERM during a run saves a checkpoint first.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--coordinator", default=None, metavar="HOST:PORT",
              help="Several processes train one run (jax.distributed): process 0's address and a free port, the same "
                   "in every process [env JAX_COORDINATOR_ADDRESS]. See docs/learning.md, 'Multi-process and "
                   "multi-host'.")
@click.option("--num-processes", type=click.IntRange(1), default=None,
              help="How many processes train the run [env JAX_NUM_PROCESSES].")
@click.option("--process-id", type=click.IntRange(0), default=None,
              help="This process's index, 0 .. num-processes - 1 [env JAX_PROCESS_ID].")
@click.option("--distributed", "detect", is_flag=True,
              help="Join a multi-process run, taking the settings not given from the cluster (SLURM's srun, Open MPI's "
                   "mpirun).")
@_check_options
@click.argument("overrides", nargs=-1)
def train(preset, data, eval_data, out, resume_dir, quiet, coordinator, num_processes, process_id, detect, deep,
          skip_checks, overrides):
    """Train a policy. OVERRIDES are section.field=value, e.g. algo.learning_rate=3e-4 train.total_env_steps=1e5."""
    import time as _time

    from vmax_sim.training.distributed import distributed_settings, initialize, is_primary, process_share

    try:  # before anything touches JAX
        settings = distributed_settings(coordinator, num_processes, process_id, detect)
        if settings is not None:
            if not (out or resume_dir):
                _fail("several processes train one run directory: name it with --out (or --resume)")
            initialize(settings)
    except InputError as error:
        _fail(one_line(error))
    primary = settings is None or is_primary()
    echo = click.echo if primary else (lambda *args, **kwargs: None)  # process 0 reports
    quiet = quiet or not primary
    share = (0, 1) if settings is None else process_share()  # each process checks its share of the shard files

    from vmax_sim.training import apply_overrides, preset_config
    from vmax_sim.training import train as run_training

    try:
        if resume_dir:
            if data or eval_data:
                _fail("--resume continues a run with its own config.json and data; drop --data / --eval-data")
            from vmax_sim.training.run import load_run_config

            resumed = load_run_config(resume_dir).data
            _check_data([resumed.train, resumed.eval], deep, skip_checks, quiet, share)
            result = run_training(None, resume_dir, resume=True, progress=not quiet, print_fn=echo,
                                  resume_overrides=overrides)
        else:
            config = preset_config(preset)
            extra = [f"data.train={data}"] * bool(data) + [f"data.eval={eval_data}"] * bool(eval_data)
            config = apply_overrides(config, extra + list(overrides))
            _check_data([config.data.train, config.data.eval], deep, skip_checks, quiet, share)
            run_dir = out or f"runs/{preset}-{_time.strftime('%Y%m%d-%H%M%S')}"
            echo(f"run directory: {run_dir}")
            result = run_training(config, run_dir, progress=not quiet, print_fn=echo)
    except (InputError, ValueError, OSError) as error:
        _fail(one_line(error))
    if result.interrupted:  # the checkpoint and the resume command were printed
        raise SystemExit(130)
    echo(f"trained {result.env_steps:,} env steps in {result.wall_s / 60:.1f} min "
         f"({result.env_steps_per_s:,.0f} env steps/s); run directory {result.run_dir}")
    if result.final_evaluation:
        from vmax_sim.evaluation import format_summary

        echo(format_summary(result.final_evaluation))


@main.command()
@click.option("--policy", required=True,
              help="Comma-separated policies: expert, constant, idm, pdm, random, or training run directories "
                   "(their latest checkpoint). Several give one comparison table.")
@click.option("--data", default=None, help="Shard directory, file or glob (default for a run: its held-out split).")
@click.option("--mode", default="non_reactive", show_default=True,
              help="Evaluation mode: non_reactive (others replay the log), reactive (controllable agents driven "
                   "along their paths), perturbed (the SDC starts off its log), adversarial (one vehicle re-planned "
                   "to cut in on the SDC), selfplay (the run's policy drives the SDC and every controllable agent: "
                   "goal-reaching, collision, off-road per agent). See docs/evaluation-modes.md.")
@click.option("--agents", default=None, help="reactive: who drives the controllable agents: idm (default), pdm, "
                                              "same (the evaluated policy: self-play), or a training run directory "
                                              "(learned traffic).")
@click.option("--max-agents", type=click.IntRange(1), default=None,
              help="reactive: at most this many agents are driven, nearest the SDC first (default 48).")
@click.option("--agents-follow-log/--agents-free", "agents_follow_log", default=None,
              help="reactive: idm, pdm and learned agents never get ahead of their own logged position along their "
                   "path (the default: they reach junctions no earlier than their logs did), or drive at their own "
                   "pace (--agents-free).")
@click.option("--perturb-sigma", type=click.FloatRange(0.0), default=None,
              help="perturbed: standard deviation of the SDC's lateral start offset, m (default 1.0; the heading "
                   "error's is 0.05 rad per m).")
@click.option("--batch-size", type=click.IntRange(1), default=8, show_default=True)
@click.option("--num-scenarios", type=click.IntRange(1), default=None, help="Evaluate only the first N.")
@click.option("--num-objects", type=click.IntRange(1), default=64, show_default=True, help="Object slots loaded.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the policies' random keys.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary (or the summaries) as JSON.")
@click.option("--out", type=click.Path(), default=None,
              help="A file ending in .json: the summary JSON (one policy). Otherwise a directory for table.md, "
                   "table.csv, episodes-<policy>.csv and summaries.json.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--gallery", "gallery_dir", type=click.Path(file_okay=False), default=None,
              help="Directory for a failure gallery: a GIF and a PNG per failed episode (and a few passed ones), "
                   "one folder per policy, and index.html.")
@click.option("--gallery-max", type=click.IntRange(0), default=50, show_default=True,
              help="Failed episodes drawn per policy (the first ones).")
@click.option("--gallery-passed", type=click.IntRange(0), default=5, show_default=True,
              help="Passed episodes drawn per policy, for comparison.")
@click.option("--difficulty", is_flag=True,
              help="Tag scenarios by difficulty and print accuracy and V-Max score per bucket (difficulty.csv "
                   "in an --out directory).")
@click.option("--view", "view_file", is_flag=False, flag_value=VIEW_DEFAULT, default=None, metavar="[FILE]",
              help="Write the rollout viewer page (failed episodes first): FILE, or rollouts.html (inside an --out "
                   "directory when one is given).")
@click.option("--view-max", type=click.IntRange(1), default=8, show_default=True,
              help="Scenarios on the --view page.")
@click.option("--brake-guard", "brake_guard", default="run", show_default=True, callback=_brake_guard_option,
              help="Training run directories drive with PDM-Closed's emergency brake over their acceleration as "
                   "the run says (run: its train.brake_guard_ttc and brake_guard_hold), without it (off: the "
                   "student alone), or with this time-to-collision threshold in seconds (0-10), +hold to also cap "
                   "the acceleration where it would lead within it (2+hold): the same weights with and without it.")
@_check_options
def evaluate(policy, data, mode, agents, max_agents, agents_follow_log, perturb_sigma, batch_size, num_scenarios,
             num_objects, seed, as_json, out, quiet, gallery_dir, gallery_max, gallery_passed, difficulty, view_file,
             view_max, brake_guard, deep, skip_checks):
    """Closed-loop evaluation: accuracy, nuPlan and V-Max scores; several policies give one comparison table."""
    from vmax_sim.evaluation import format_summary
    from vmax_sim.evaluation.evaluate import partial_note
    from vmax_sim.evaluation.extras import EvaluationExtras
    from vmax_sim.evaluation.modes import parse_mode
    from vmax_sim.evaluation.report import (
        compare_policies,
        format_markdown,
        is_run_directory,
        split_policies,
        write_evaluation_settings,
        write_report,
    )
    from vmax_sim.training.interrupt import StopRequests
    from vmax_sim.visualization.view import run_data

    if mode == "selfplay":
        _evaluate_selfplay(policy, data, num_scenarios, batch_size, seed, as_json, out, quiet, deep, skip_checks)
        return
    try:
        mode_name = mode
        traffic = _learned_traffic(agents)
        mode = parse_mode(mode, agents=agents if traffic is None else "idm", perturb_sigma=perturb_sigma,
                          max_agents=max_agents, seed=seed, agents_follow_log=agents_follow_log)
        if traffic is not None:
            mode = dataclasses.replace(mode, agents="learned", agent_policy=traffic, agent_run=agents)
        entries = split_policies(policy)
        if brake_guard is not None and not any(is_run_directory(entry) for entry in entries):
            raise InputError("--brake-guard acts on training run directories; --policy names none")
        _check_data([data or ""], deep, skip_checks, quiet)  # without --data a run's held-out split is checked as read
        out_dir = out if out and not out.endswith(".json") else None
        if view_file == VIEW_DEFAULT and out_dir:
            view_file = str(Path(out_dir) / VIEW_DEFAULT)
        extras = EvaluationExtras.create(gallery_dir, gallery_max, gallery_passed, difficulty, view_file, view_max)
        with StopRequests(on_first=_evaluation_stop_notice) as stop:  # Ctrl-C / SIGTERM: partial results
            runs = compare_policies(entries, data, mode, num_scenarios=num_scenarios, batch_size=batch_size,
                                    num_objects=num_objects, seed=seed, progress=not quiet,  # stderr: --json clean
                                    print_fn=lambda line: click.echo(line, err=True), on_batch=extras.on_batch,
                                    run_evaluator=_run_evaluator(brake_guard),
                                    stop=stop)
        summaries = {run.name: run.result.summary for run in runs}
        if len(runs) == 1:
            text = json.dumps(runs[0].result.summary, indent=2)
            click.echo(text if as_json else format_summary(runs[0].result.summary))
        else:
            text = json.dumps(summaries, indent=2)
            click.echo(text if as_json else format_markdown(runs))
        if out and out.endswith(".json"):
            Path(out).parent.mkdir(parents=True, exist_ok=True)
            Path(out).write_text(text)
        elif out:
            write_report(out, runs)
            (Path(out) / "summaries.json").write_text(json.dumps(summaries, indent=2))
            write_evaluation_settings(out, {
                "policies": entries, "data": data, "mode": mode_name, "agents": agents, "max_agents": max_agents,
                "perturb_sigma": perturb_sigma, "seed": seed, "num_objects": num_objects,
                "num_scenarios": num_scenarios})
            if not as_json:
                click.echo(f"wrote {out}/table.md, table.csv, summaries.json, evaluation.json and "
                           "episodes-<policy>.csv")
        if stop.requested:
            click.echo(f"{partial_note(summaries)}; {stop.signal_name} stopped the evaluation", err=True)
            raise SystemExit(130)
        extras.finish(runs, out, show_tables=not as_json, progress=not quiet and not as_json, print_fn=click.echo,
                      note=f"data: {data or 'the held-out split of each run'}",
                      data=run_data(entries, data, lambda line: click.echo(line, err=True)) if view_file else None,
                      mode_name=mode.name)
    except (InputError, ValueError, OSError) as error:
        _fail(one_line(error))


def _learned_traffic(agents: str | None):
    """--agents RUN_DIR: (policy, params, observation settings) of the run, else None (a rule driver's name)."""
    if agents is None or not (Path(agents) / "config.json").is_file():
        return None
    from vmax_sim.training.run_policy import load_trained_policy

    loaded = load_trained_policy(agents)
    return loaded.policy, loaded.params, loaded.config.obs


def _evaluate_selfplay(policy, data, num_scenarios, batch_size, seed, as_json, out, quiet, deep, skip_checks) -> None:
    """`evaluate --mode selfplay`: each run's policy drives every agent of the scenes (vmax_sim.evaluation.selfplay)."""
    from vmax_sim.evaluation.selfplay import format_selfplay
    from vmax_sim.training.run_policy import evaluate_selfplay_run

    try:
        runs = [entry.strip() for entry in policy.split(",") if entry.strip()]
        for run in runs:
            if not (Path(run) / "config.json").is_file():
                raise InputError(f"{run}: --mode selfplay drives every agent with a trained policy; give training run "
                                 f"directories, not {run!r}")
        _check_data([data or ""], deep, skip_checks, quiet)
        summaries = {}
        for run in runs:
            result = evaluate_selfplay_run(run, data, num_scenarios, batch_size, progress=not quiet, seed=seed)
            summaries[run] = {**result.summary(), "data": data or "the run's held-out split"}
        if as_json:
            click.echo(json.dumps(summaries if len(runs) > 1 else summaries[runs[0]], indent=2))
        else:
            click.echo("\n".join(format_selfplay(summary, f"self-play {run}") for run, summary in summaries.items()))
        if out:
            target = Path(out) if out.endswith(".json") else Path(out) / "selfplay.json"
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(json.dumps(summaries, indent=2))
    except (InputError, ValueError, OSError) as error:
        _fail(one_line(error))


def _evaluation_stop_notice(signal_name: str) -> None:
    click.echo(f"\n{signal_name}: finishing the batch in flight, then the partial results "
               "(once more to stop at once)", err=True)


@main.command()
@click.option("--out", default="runs/demo", show_default=True, type=click.Path(file_okay=False))
@click.option("--num-scenarios", type=click.IntRange(1), default=160, show_default=True,
              help="Synthetic training scenarios.")
@click.option("--num-eval-scenarios", type=click.IntRange(1), default=32, show_default=True,
              help="Held-out synthetic scenarios (next seed).")
@click.option("--train-steps", type=click.IntRange(1), default=24_000, show_default=True,
              help="Environment steps of the demo's training run.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--workers", type=click.IntRange(1), default=None, help="Conversion workers (default: one per core).")
def demo(out, num_scenarios, num_eval_scenarios, train_steps, seed, workers):
    """Synthetic scenarios -> shards -> inspect -> short training run -> evaluation table -> pictures."""
    from vmax_sim.demo import run_demo

    try:
        run_demo(out, num_scenarios=num_scenarios, num_eval_scenarios=num_eval_scenarios, seed=seed,
                 workers=workers, train_steps=train_steps, print_fn=click.echo)
    except (InputError, ValueError, OSError) as error:
        _fail(one_line(error))


@main.command()
@click.argument("target", metavar="RUN_EVAL_OR_SHARDS")
@click.option("--policy", default=None,
              help="Comma-separated policies (expert, constant, idm, pdm, random or run directories). Default: "
                   "constant,idm for shards; for a training run directory its own policy (these are added).")
@click.option("--num-scenarios", type=click.IntRange(1), default=4, show_default=True,
              help="Scenarios shown (the first ones).")
@click.option("--data", default=None, help="With a run directory: shards to use instead of its held-out split.")
@click.option("--num-objects", type=click.IntRange(1), default=64, show_default=True, help="Object slots simulated.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out", type=click.Path(dir_okay=False), default="rollouts.html", show_default=True,
              help="The self-contained HTML file to write.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def view(target, policy, num_scenarios, data, num_objects, seed, out, quiet):
    """Web viewer of closed-loop rollouts: logged and simulated SDCs, per-step metrics (docs/viewer.md).

    RUN_EVAL_OR_SHARDS: shards (the policies on their first scenarios), a training run directory (its policy on
    its held-out split) or a `vmax-sim evaluate --out` directory (its policies and mode, failed scenarios first).
    """
    from vmax_sim.evaluation.report import split_policies
    from vmax_sim.visualization.view import write_rollout_view

    try:
        policies = split_policies(policy) if policy is not None else None
        result = write_rollout_view(target, policies, out=out, num_scenarios=num_scenarios, data=data,
                                    num_objects=num_objects, seed=seed, progress=not quiet,
                                    print_fn=lambda line: click.echo(line, err=True))
    except (InputError, ValueError, OSError) as error:
        _fail(one_line(error))
    click.echo(f"{result.num_embedded} scenario(s); {result.size_bytes / 1e6:.1f} MB", err=True)
    click.echo(str(result.out))


@main.command()
@click.option("--policy", required=True,
              help="Comma-separated: log, constant, idm, or training run directories (their latest checkpoint; the "
                   "policy drives the SDC and every evaluated agent, sampling its actions).")
@click.option("--data", default=None,
              help="Shard directory, file or glob; 'synthetic' for the held-out synthetic split (seed 1, 100 scenes). "
                   "Default for a run directory: its held-out split.")
@click.option("--rollouts", type=click.IntRange(1), default=32, show_default=True,
              help="Rollouts per scene (WOSAC: 32). A deterministic policy without --action-noise runs once and counts "
                   "as this many identical rollouts.")
@click.option("--scenes", type=click.IntRange(1), default=None, help="Score only the first K scenes.")
@click.option("--max-agents", type=click.IntRange(1), default=32, show_default=True,
              help="Controllable agents evaluated (and driven) besides the SDC, nearest first.")
@click.option("--action-noise", type=click.FloatRange(0.0), default=0.0, show_default=True,
              help="Standard deviation (m/s^2) of a noise added to every driven object's acceleration each step, so "
                   "that a deterministic policy's rollouts differ.")
@click.option("--num-objects", type=click.IntRange(1), default=64, show_default=True, help="Object slots loaded.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the rollouts' random keys.")
@click.option("--json", "as_json", is_flag=True, help="Print the summaries as JSON.")
@click.option("--out", type=click.Path(dir_okay=False), default=None, help="Also write the summaries JSON here.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def realism(policy, data, rollouts, scenes, max_agents, action_noise, num_objects, seed, as_json, out, quiet):
    """Sim-agent realism (WOSAC-style meta-metric): likelihood of the logged future under each feature's
    histogram over N rollouts, weighted as the 2024 challenge (docs/realism.md)."""
    from scenariomax.progress import Progress
    from vmax_sim.data import DataConfig
    from vmax_sim.evaluation.realism_rollouts import ROLLOUT_POLICIES
    from vmax_sim.evaluation.realism_run import format_realism, realism_for_policy
    from vmax_sim.evaluation.report import expected_num_scenarios

    notes = lambda line: click.echo(line, err=True)  # noqa: E731  (stdout may carry --json)
    try:
        summaries = []
        for entry in [part.strip() for part in policy.split(",") if part.strip()]:
            if entry not in ROLLOUT_POLICIES and not Path(entry).is_dir():
                raise InputError(f"--policy {entry!r}: neither one of {', '.join(ROLLOUT_POLICIES)} nor a training "
                                 "run directory")
            trained = _realism_run(entry, data, notes) if entry not in ROLLOUT_POLICIES else None
            if trained is None and not data:
                raise InputError(f"--policy {entry}: give --data (shards, or 'synthetic')")
            data_config = trained.data_config if trained else DataConfig(
                path=_realism_data(data, num_objects, notes), num_objects=num_objects)
            total = expected_num_scenarios(data_config.path, scenes)
            with Progress(f"realism {Path(entry).name}", total, "scenes", enabled=not quiet) as shown:
                result = realism_for_policy(entry, data_config, trained=trained, num_rollouts=rollouts,
                                            num_scenes=scenes, max_agents=max_agents, action_noise=action_noise,
                                            seed=seed, progress=shown)
            summaries.append({**result.summary, "data": data_config.path})
    except (InputError, ValueError, OSError) as error:
        _fail(one_line(error))
    text = json.dumps(summaries if len(summaries) > 1 else summaries[0], indent=2)
    click.echo(text if as_json else format_realism(summaries))
    if out:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(text)


def _realism_data(data: str, num_objects: int, print_fn) -> str:
    """A shard path, or the held-out synthetic split for 'synthetic'."""
    if data != "synthetic":
        return data
    from vmax_sim.training.run import synthetic_split

    return synthetic_split(100, 1, num_objects, print_fn)


def _realism_run(run_dir: str, data: str | None, print_fn):
    """A training run directory as realism's `TrainedRun` (its checkpoint, learner, configs and data sizes)."""
    from vmax_sim.evaluation.realism_run import TrainedRun
    from vmax_sim.training.run import components, data_config, resolve_eval_data
    from vmax_sim.training.run_policy import load_trained_policy

    loaded = load_trained_policy(run_dir)
    env = components(loaded.config)[0]
    path = _realism_data(data, loaded.config.data.num_objects, print_fn) if data else resolve_eval_data(
        loaded.config, print_fn)
    return TrainedRun(name=loaded.policy.name, learner=loaded.learner, params=loaded.params, env_config=env.env_config,
                      obs_config=loaded.config.obs, data_config=data_config(loaded.config, path, batch_size=1))


@main.group()
def cache() -> None:
    """What V-Max keeps under $VMAX_CACHE_DIR (default ~/.cache/vmax_sim): the embedded synthetic splits and the
    map-index cache. Both are rebuilt when needed."""


@cache.command("info")
def cache_info():
    """Each cached synthetic split and map-index version with its size."""
    from vmax_sim.data.cache_admin import format_cache_info

    click.echo(format_cache_info())


@cache.command("clear")
@click.argument("kind", type=click.Choice(["all", "synthetic", "map_index"]), default="all")
def cache_clear(kind):
    """Delete the cached synthetic splits, map indices, or both (the default)."""
    from vmax_sim.data.cache_admin import clear_cache, human_bytes
    from vmax_sim.data.config import cache_dir

    try:
        freed = clear_cache(kind)
    except OSError as error:
        _fail(one_line(error))
    click.echo(f"freed {human_bytes(freed)} under {cache_dir()}")


if __name__ == "__main__":
    main()
