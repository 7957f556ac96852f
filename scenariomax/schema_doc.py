"""Generates `docs/schema.md` from the schema file (`scenariomax schema-doc` rewrites it)."""

from __future__ import annotations

from scenariomax.schema import load_schema


def _shape_text(shape) -> str:
    return "[" + ", ".join(str(d) for d in shape) + "]" if shape else "scalar (1 value)"


def render_schema_markdown() -> str:
    schema = load_schema()
    lines = [
        f"# Shard schema `{schema.name}` v{schema.version}",
        "",
        "<!-- Generated from schemas/shard_schema.v1.json by `scenariomax schema-doc`; do not edit by hand. -->",
        "",
        schema.description,
        "",
        "Files: `OUT/<split>-XXXXX-of-YYYYY.tfrecord` (TFRecord framing, masked CRC32C) plus `OUT/manifest.json`.",
        "Keys in the `waymax` group follow the WOMD motion tf.Example layout that Waymax's dataloader reads;",
        "`vmax` keys are V-Max extras and never change the meaning of a Waymax key.",
        "",
        "## Dimensions",
        "",
        "| dim | default | meaning |",
        "|---|---|---|",
    ]
    lines += [f"| `{name}` | {size} | {schema.dim_meanings[name]} |" for name, size in schema.dims.items()]
    lines += ["", "## Features", "", "| key | dtype | shape | pad | group | meaning |", "|---|---|---|---|---|---|"]
    for spec in schema.features:
        layout = " (time-major)" if spec.layout == "time_major" else ""
        lines.append(f"| `{spec.key}` | {spec.dtype} | {_shape_text(spec.shape)}{layout} | `{spec.pad!r}` | "
                     f"{spec.group} | {spec.meaning} |")
    for name, values in schema.enums.items():
        lines += ["", f"## Enum `{name}`", "", "| value | name |", "|---|---|"]
        lines += [f"| {value} | {label} |" for value, label in values.items()]
    return "\n".join(lines) + "\n"
