"""Ctrl-C / SIGTERM during `vmax-sim evaluate`: the episodes finished so far are summarised, marked partial
(how many of how many), the report files are written, and the command exits 130."""

from __future__ import annotations

import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vmax_sim.evaluation.evaluate import EvaluationResult, format_summary, mark_partial, partial_note

BIN = Path(sys.executable).parent


def _result(num_episodes: int) -> EvaluationResult:
    summary = {"policy": "expert", "mode": "non_reactive", "num_episodes": num_episodes, "num_unjudged": 0,
               "accuracy": 1.0, "accuracy_at_fault": 1.0, "nuplan_score": 0.9, "vmax_score": 0.9, "metrics": {}}
    return EvaluationResult(summary=summary, episodes={}, scenario_ids=tuple(str(i) for i in range(num_episodes)))


def test_a_partial_result_says_how_many_episodes_of_how_many():
    partial = mark_partial(_result(8), 32)
    assert partial.summary["partial"] == {"episodes": 8, "of": 32}
    assert "episodes: 8 of 32 (PARTIAL: interrupted)" in format_summary(partial.summary).splitlines()[0]
    assert partial_note({"expert": partial.summary}) == "partial results (interrupted): expert: 8 of 32 episodes"
    assert partial_note({"expert": _result(8).summary}) is None  # a finished run says nothing


def _read_until(fd: int, pattern: str, timeout_s: float) -> str:
    """Reads a pseudo-terminal until `pattern` appears (the progress bar is drawn only on a terminal)."""
    seen, deadline = "", time.monotonic() + timeout_s
    while time.monotonic() < deadline and not re.search(pattern, seen):
        ready, _, _ = select.select([fd], [], [], 1.0)
        if ready:
            try:
                seen += os.read(fd, 4096).decode(errors="replace")
            except OSError:  # the child closed the terminal
                break
    return seen


@pytest.fixture(scope="module")
def eight_scenarios(tmp_path_factory) -> Path:
    from scenariomax import ConvertSettings, Sizes, SyntheticSource, convert, make_transform

    out = tmp_path_factory.mktemp("interrupt") / "shards"
    sizes = Sizes(num_objects=16, num_roadgraph=5000)
    transform, transform_settings = make_transform()
    convert(SyntheticSource(num_scenarios=8, seed=1, sizes=sizes),
            ConvertSettings(out=out, workers=1, sizes=sizes, progress=False, transform=transform,
                            transform_settings=transform_settings))
    return out


@pytest.mark.slow  # the evaluation program compiles before its first batch (~20-60 s on 2 cores)
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_prints_the_partial_summary_writes_the_report_and_exits_130(eight_scenarios, tmp_path, signum):
    out = tmp_path / "report"
    primary, secondary = pty.openpty()
    command = [str(BIN / "vmax-sim"), "evaluate", "--policy", "expert,constant", "--data", str(eight_scenarios),
               "--batch-size", "1", "--num-objects", "16", "--out", str(out)]
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=secondary, text=True)
    os.close(secondary)
    try:
        # the bar is drawn once the handler is installed and the data counted: a signal now stops after a batch
        _read_until(primary, r"evaluating expert,constant", 180)
        child.send_signal(signum)
        stdout, _ = child.communicate(timeout=300)
        stderr = _read_until(primary, r"stopped the evaluation", 5)
    finally:
        child.kill()
        os.close(primary)
    assert child.returncode == 130, stdout + stderr
    match = re.search(r"partial results \(interrupted\): expert: (\d+) of 8 episodes, constant: (\d+) of 8 episodes; "
                      + signal.Signals(signum).name, stderr)
    assert match and 1 <= int(match.group(1)) < 8 and match.group(1) == match.group(2), stderr
    assert "Traceback" not in stderr
    assert "| Accuracy" in stdout or "Accuracy" in stdout, stdout  # the comparison table of the finished episodes
    summaries = json.loads((out / "summaries.json").read_text())
    assert summaries["expert"]["partial"] == {"episodes": int(match.group(1)), "of": 8}
    assert "partial results (interrupted)" in (out / "table.md").read_text()
