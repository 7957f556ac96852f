from pathlib import Path

from scenariomax.schema_doc import render_schema_markdown

DOC = Path(__file__).resolve().parents[2] / "docs" / "schema.md"


def test_schema_doc_is_current():
    assert DOC.read_text() == render_schema_markdown(), "docs/schema.md is stale: run `scenariomax schema-doc`"


def test_schema_doc_lists_every_key():
    text = render_schema_markdown()
    assert "`state/past/x`" in text and "`path_samples/on_route`" in text and "`vmax/lane/successors`" in text
