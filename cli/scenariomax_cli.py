"""`scenariomax` command line: thin click commands that build a config and call the library."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from scenariomax.schema import Sizes
from scenariomax.sources.registry import DATASETS


class _OneLineErrors(click.Group):
    """Bad input ends with one line naming the file and the problem, never a traceback."""

    def invoke(self, ctx):
        from scenariomax.codec import SchemaError
        from scenariomax.errors import InputError, one_line
        from scenariomax.io.tfrecord import RecordError
        from scenariomax.pipeline import ConversionError
        from scenariomax.shards import ShardReadError

        try:
            return super().invoke(ctx)
        except (ConversionError, InputError, RecordError, ShardReadError, SchemaError, OSError) as error:
            raise click.ClickException(one_line(error)) from error


@click.group(cls=_OneLineErrors)
@click.version_option(package_name="vmax", prog_name="scenariomax")
def main() -> None:
    """Convert driving datasets into V-Max shards, inspect and validate them."""


def _sizes(num_objects: int, roadgraph_points: int) -> Sizes:
    return Sizes(num_objects=num_objects, num_roadgraph=roadgraph_points)


def _without_path(path: str, message: str) -> str:
    """`message` without its leading `path: ` (repeated when layers each added it): the caller prints the path
    itself, once."""
    prefix = f"{path}: "
    while message.startswith(prefix):
        message = message[len(prefix):]
    return message


def _print_summary(result) -> None:
    width = max(len(label) for label, _ in result.summary_rows())
    click.echo("")
    for label, value in result.summary_rows():
        click.echo(f"  {label:<{width}}  {value}")
    for failure in result.failures[:10]:
        reason = _without_path(failure["unit"], failure["reason"])
        click.echo(f"  failed: {failure['unit']} [{failure['scenario']}]: {reason}", err=True)
    if len(result.failures) > 10:
        click.echo(f"  ... and {len(result.failures) - 10} more failures (see manifest.json)", err=True)


def _run_conversion(source, out, workers, shard_size, resume, overwrite, split, engine, address, sizes, enrich,
                    num_paths, points_per_path, compression="none") -> None:
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert

    transform, transform_settings = make_transform(enabled=enrich, num_paths=num_paths,
                                                   points_per_path=points_per_path)
    settings = ConvertSettings(
        out=Path(out), split=split, shard_size=shard_size, workers=workers, resume=resume, overwrite=overwrite,
        sizes=sizes, engine=engine, ray_address=address, progress=True,
        transform=transform, transform_settings=transform_settings, compression=compression,
    )
    result = convert(source, settings)
    _print_summary(result)
    if result.num_scenarios == 0:
        why = "see the failures above" if result.num_failures else "they hold no scenario"
        click.echo(f"error: no scenario could be converted from the {result.num_units} input(s) ({why}); "
                   "check that they are what the command expects", err=True)
    if not result.ok:
        sys.exit(1)


_common_pipeline_options = [
    click.option("--out", required=True, type=click.Path(file_okay=False), help="Output directory."),
    click.option("--workers", type=click.IntRange(min=1), default=None,
                 help="Worker processes (default: one per core; with --engine ray on a cluster, its CPUs)."),
    click.option("--shard-size", type=click.IntRange(min=1), default=1000, show_default=True,
                 help="Scenarios per shard."),
    click.option("--resume", is_flag=True, help="Continue an interrupted conversion in --out."),
    click.option("--overwrite", is_flag=True,
                 help="Replace the conversion in --out (deletes only the files its manifest.json lists)."),
    click.option("--split", default="train", show_default=True, help="Split name used in shard file names."),
    click.option("--engine", type=click.Choice(["process", "ray"]), default="process", show_default=True),
    click.option("--address", default=None,
                 help="Ray cluster address (with --engine ray; default $RAY_ADDRESS, else a local Ray instance)."),
    click.option("--num-paths", type=int, default=10, show_default=True, help="SDC paths per scenario."),
    click.option("--points-per-path", type=int, default=300, show_default=True, help="Points per SDC path."),
    click.option("--compression", type=click.Choice(["none", "gzip"]), default="none", show_default=True,
                 help="gzip: TFRecord GZIP shards, 5-25% of the plain bytes (tf.data: compression_type='GZIP'); "
                      "every reader here detects it. none: the plain files Waymax reads."),
]


def _pipeline_options(fn):
    for option in reversed(_common_pipeline_options):
        fn = option(fn)
    return fn


def _synthetic_knobs(ctx, param, items):
    """--synthetic-knob NAME=VALUE (repeatable) -> SyntheticKnobs, or None when none is given."""
    if not items:
        return None
    from scenariomax.sources.synthetic.knobs import SyntheticKnobs

    try:
        return SyntheticKnobs.from_items(items)
    except ValueError as error:
        raise click.BadParameter(str(error).splitlines()[0], ctx=ctx, param=param) from None


@main.command()
@click.option("--dataset", type=click.Choice(list(DATASETS)),
              default="synthetic", show_default=True)
@click.option("--src", default=None,
              help="Raw input files, directory or glob (real datasets; nuPlan: default $NUPLAN_DB_FILES).")
@click.option("--maps", default=None, help="nuPlan maps root (default $NUPLAN_MAPS_ROOT).")
@click.option("--num-scenarios", type=int, default=100, show_default=True, help="Synthetic: how many.")
@click.option("--seed", type=int, default=0, show_default=True, help="Synthetic: random seed.")
@click.option("--synthetic-knob", "knobs", multiple=True, metavar="NAME=VALUE", callback=_synthetic_knobs,
              help="Synthetic: a randomisation knob (repeatable; ranges as lo:hi), e.g. traffic_density=2, "
                   "position_noise_m=0.3, lane_width_m=2.8:4.2, speed_limit_scale=1.2, driver_style_spread=1.5, "
                   "parked_fraction=0:0.3, topology_weights=intersection4:2,merge:1.")
@click.option("--stride-steps", type=int, default=None, help="nuPlan: also cut a scenario every N steps.")
@click.option("--num-objects", type=int, default=128, show_default=True, help="Object slots per scenario.")
@click.option("--roadgraph-points", type=int, default=30000, show_default=True, help="Roadgraph points.")
@click.option("--no-enrich", is_flag=True, help="Skip enrichment (paths, controllable labels, lights).")
@click.option("--sdc-paths", type=click.Choice(["auto", "waymo", "reconstruct"]), default="auto", show_default=True,
              help="WOMD Scenario protos: Waymo's own SDC paths (1.3.1+) when present (auto), only Waymo's, or "
                   "always our reconstruction.")
@_pipeline_options
def convert(dataset, src, maps, num_scenarios, seed, knobs, stride_steps, num_objects, roadgraph_points, no_enrich,
            sdc_paths, out, workers, shard_size, resume, overwrite, split, engine, address, num_paths,
            points_per_path, compression):
    """Convert a dataset (or generate synthetic scenarios) into shards + manifest.json."""
    import dataclasses

    from scenariomax.sources.registry import make_source

    if knobs is not None and dataset != "synthetic":
        raise click.UsageError(f"--synthetic-knob applies to --dataset synthetic, not {dataset}")

    sizes = Sizes(num_objects=num_objects, num_roadgraph=roadgraph_points, num_paths=num_paths,
                  num_points_per_path=points_per_path)
    if sdc_paths != "auto" and dataset != "womd":
        raise click.UsageError(f"--sdc-paths applies to --dataset womd, not {dataset}")
    source = make_source(dataset, src=src, sizes=sizes, num_scenarios=num_scenarios, seed=seed, maps=maps,
                         stride_steps=stride_steps, sdc_paths=sdc_paths,
                         orient_edges=no_enrich)  # the enrichment orients road edges itself: once is enough
    if knobs is not None:
        source = dataclasses.replace(source, knobs=knobs)
    _run_conversion(source, out, workers, shard_size, resume, overwrite, split, engine, address, sizes,
                    not no_enrich, num_paths, points_per_path, compression)


@main.command("build-sdc-paths")
@click.argument("src")
@_pipeline_options
def build_sdc_paths(src, out, workers, shard_size, resume, overwrite, split, engine, address, num_paths,
                    points_per_path, compression):
    """Enrich existing shards or raw WOMD tf.Example files with SDC paths (and the other enrichments)."""
    from scenariomax.sources.shard_records import ShardRecordsSource

    sizes = Sizes(num_paths=num_paths, num_points_per_path=points_per_path)
    _run_conversion(ShardRecordsSource(src=src), out, workers, shard_size, resume, overwrite, split, engine,
                    address, sizes, True, num_paths, points_per_path, compression)


@main.command()
@click.argument("path")
@click.option("--json", "as_json", is_flag=True, help="Print the statistics as JSON.")
@click.option("--render", type=click.Path(dir_okay=False), default=None, help="Draw one scenario to this PNG.")
@click.option("--scenario", "scenario_id", default=None, help="Scenario id to show/draw (default: the first).")
@click.option("--max-records", type=int, default=None, help="Only look at the first N records.")
def inspect(path, as_json, render, scenario_id, max_records):
    """Statistics, schema validation and pictures of shards."""
    from scenariomax.inspect import format_report, inspect_shards, inspection_ok, load_scenario

    stats = inspect_shards(path, scenario_id=scenario_id, max_records=max_records)  # unknown --scenario: fails first
    click.echo(json.dumps(stats, indent=1) if as_json else format_report(stats))
    for warning in stats["manifest"]["warnings"]:
        click.echo(f"warning: {warning}", err=True)
    if render:
        from scenariomax.render import render_scenario

        scenario = load_scenario(path, scenario_id)
        written = render_scenario(scenario, render)
        click.echo(f"rendered {scenario.scenario_id} -> {written}", err=True)
    if not inspection_ok(stats):
        num_bad, manifest_problems = stats["validation"]["num_bad_records"], len(stats["manifest"]["problems"])
        click.echo(f"{path}: {num_bad} bad record(s), {manifest_problems} manifest problem(s); "
                   "`scenariomax validate` lists them all", err=True)
        sys.exit(1)


@main.command()
@click.argument("paths", nargs=-1, required=True, metavar="PATH...")
@click.option("--deep", is_flag=True, help="Also check every value against plausible physical ranges "
                                           "(docs/validate.md).")
def validate(paths, deep):
    """Exit 0 if every record under each PATH matches the schema and each folder is the complete output its
    manifest.json lists (shards, record counts, sha256, unique scenario ids); else one line per problem and
    exit 1. The problems and the verdict go to stdout (they are the command's output), warnings to stderr."""
    from scenariomax.validate import combine_reports, find_files_to_check, format_bad, validate_shards

    for path in paths:  # a missing or empty path is a one-line error before any long validation starts
        find_files_to_check(path)
    reports = []
    for path in paths:
        report = validate_shards(path, deep=deep)
        for entry in report.bad:
            click.echo(format_bad(entry))
        for warning in report.warnings:
            click.echo(f"warning: {warning}", err=True)
        reports.append(report)
    total = combine_reports(reports)
    click.echo(_validation_verdict(total))
    sys.exit(0 if total.ok else 1)


def _validation_verdict(report) -> str:
    """`N records in M files: all valid` (or `: K problems`), noting when a folder had no manifest to check."""
    verdict = f"{len(report.bad)} problems" if report.bad else "all valid"
    if report.warnings and not report.bad:
        verdict += " (completeness not checked: no manifest.json)"
    return f"{report.num_records} records in {report.num_files} files: {verdict}"


@main.command()
@click.argument("path")
@click.option("--scenario", "scenario_id", default=None, help="Show only this scenario id (serve: open it first).")
@click.option("--out", type=click.Path(dir_okay=False), default="view.html", show_default=True,
              help="The self-contained HTML file to write.")
@click.option("--max-scenarios", type=click.IntRange(1), default=20, show_default=True,
              help="HTML: embed at most this many scenarios (the first ones).")
@click.option("--serve", is_flag=True, help="Serve every scenario from 127.0.0.1 instead (loaded on demand).")
@click.option("--port", type=click.IntRange(0, 65535), default=8765, show_default=True, help="--serve: the port.")
def view(path, scenario_id, out, max_scenarios, serve, port):
    """Offline web viewer of shards: map, objects, lights, paths, timeline (docs/viewer.md)."""
    if serve:
        from scenariomax.view import serve_view

        try:
            serve_view(path, port=port, scenario_id=scenario_id, print_fn=click.echo)
        except OSError as error:
            raise click.ClickException(str(error).splitlines()[0]) from None
        return
    from scenariomax.view import write_view

    result = write_view(path, out, scenario_id=scenario_id, max_scenarios=max_scenarios)
    click.echo(f"{result.note}; {result.size_bytes / 1e6:.1f} MB", err=True)
    click.echo(str(result.out))


@main.command("schema-doc")
@click.option("--out", type=click.Path(dir_okay=False), default="docs/schema.md", show_default=True)
def schema_doc(out):
    """Regenerate the schema documentation from schemas/."""
    from scenariomax.schema_doc import render_schema_markdown

    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(render_schema_markdown())
    click.echo(f"wrote {out}")


if __name__ == "__main__":
    main()
