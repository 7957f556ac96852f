"""The viewer page: one HTML file with the CSS, the JavaScript and (when embedded) the scenes inlined.

The template, style sheet and script are package data of `scenariomax.view` (viewer.html, viewer.css,
viewer.js), read with importlib.resources so the page works from an installed wheel. Nothing on the
page loads from the network: embedded scenes are base64 text in `<script type="application/octet-stream">`
elements, decoded by the page only when selected; a served page fetches them from its own server.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import json
import os
from collections.abc import Sequence
from importlib import resources
from pathlib import Path

from scenariomax.errors import InputError
from scenariomax.view.index import ShardIndex, compact_summary
from scenariomax.view.scene import error_scene, pack_scene, scene_from_scenario

DEFAULT_MAX_SCENARIOS = 20
_MARKERS = ("__TITLE__", "__CSS__", "__CONFIG__", "__SCENES__", "__JS__")


def _asset(name: str) -> str:
    return resources.files("scenariomax.view").joinpath(name).read_text(encoding="utf-8")


def _script_safe(text: str) -> str:
    """Text that cannot close the <script> element it sits in."""
    return text.replace("</", "<\\/").replace("<!--", "<\\!--")


def render_page(config: dict, scenes: Sequence[bytes] = ()) -> str:
    """The page HTML. config: mode ("embedded" or "serve"), title, note, entries (id, file, record,
    summary), file_errors, initial (entry to open first). scenes: packed scenes, one per entry (embedded)."""
    config_text = _script_safe(json.dumps(config, separators=(",", ":"), allow_nan=False))
    scene_tags = "\n".join(f'<script type="application/octet-stream" id="scene-{i}">'
                           f"{base64.b64encode(blob).decode('ascii')}</script>" for i, blob in enumerate(scenes))
    values = {"__TITLE__": html.escape(config.get("title", "V-Max viewer")), "__CSS__": _asset("viewer.css"),
              "__CONFIG__": config_text, "__SCENES__": scene_tags, "__JS__": _script_safe(_asset("viewer.js"))}
    pieces, rest = [], _asset("viewer.html")
    for marker in _MARKERS:  # in template order; inserted text is never searched for markers again
        before, rest = rest.split(marker, 1)
        pieces += [before, values[marker]]
    return "".join(pieces + [rest])


@dataclasses.dataclass(frozen=True)
class ViewResult:
    out: Path
    num_embedded: int
    num_records: int
    size_bytes: int
    chosen: str | None = None  # the scenario id asked for

    @property
    def note(self) -> str:
        if self.chosen is not None:
            return f"scenario {self.chosen} (1 of {self.num_records} records)"
        if self.num_embedded < self.num_records:
            return (f"{self.num_embedded} of {self.num_records} scenarios embedded (the cap); use --scenario ID, "
                    f"--max-scenarios N or --serve for the others")
        return f"{self.num_records} scenario(s)"


def scene_for(index: ShardIndex, position: int) -> tuple[bytes, dict]:
    """(packed scene, entry for the page's list) of record `position`: decoded, validated and summarised."""
    check = index.check(position)
    entry = index.describe(position)
    summary = compact_summary(check)
    entry["summary"] = summary
    if check.scenario is None:
        reason = "; ".join(check.problems) or "the record cannot be decoded"
        return error_scene(reason, entry["id"]), entry
    meta, arrays = scene_from_scenario(check.scenario, summary=summary, problems=check.problems)
    return pack_scene(meta, arrays), entry


def write_page(out: str | os.PathLike, config: dict, scenes: Sequence[bytes]) -> Path:
    out = Path(out)
    if out.exists() and out.is_dir():
        raise InputError(f"{out}: is a directory; --out names the HTML file to write")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render_page(config, scenes), encoding="utf-8")
    return out


def write_view(path: str | os.PathLike, out: str | os.PathLike = "view.html", *, scenario_id: str | None = None,
               max_scenarios: int = DEFAULT_MAX_SCENARIOS) -> ViewResult:
    """Writes one self-contained HTML viewer of the shards under `path`: the scenario `scenario_id` only,
    or the first `max_scenarios` records. InputError (one line) for a missing path, no shards or an
    unknown scenario id."""
    if max_scenarios < 1:
        raise InputError("--max-scenarios must be at least 1")
    index = ShardIndex.build(path)
    positions = [index.find(scenario_id)] if scenario_id is not None else list(range(min(max_scenarios, len(index))))
    scenes, entries = [], []
    for position in positions:
        blob, entry = scene_for(index, position)
        scenes.append(blob)
        entries.append(entry)
    result_note = ViewResult(Path(out), len(positions), len(index), 0, scenario_id).note
    config = {"mode": "embedded", "title": f"V-Max viewer - {path}", "note": result_note, "entries": entries,
              "file_errors": list(index.file_errors), "initial": 0}
    written = write_page(out, config, scenes)
    return ViewResult(written, len(positions), len(index), written.stat().st_size, scenario_id)


__all__ = ["DEFAULT_MAX_SCENARIOS", "ViewResult", "render_page", "scene_for", "write_page", "write_view"]
