"""Every shell line of the README's command block runs, on a tiny synthetic dataset, in a temporary folder.

The command block is a synopsis (`[optional]`, `{a,b}` choices, `...`, placeholders); each line is expanded
mechanically into the commands a user would type, with every optional group included, one command per choice:
a wrong option, sub-command, preset, override or path in the README fails here. Not run: the README's first two
shell blocks (the install commands: `.ci/run` runs the second, tests/packaging/test_wheel.py the first's
`vmax-sim demo`). Placeholders and the substitutions that keep the run short are the tables below, each with
its reason; nothing else is changed.
"""

from __future__ import annotations

import itertools
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
REALDATA = REPO.parent / "shared" / "realdata"
BIN = Path(sys.executable).parent

# What each placeholder stands for (RAW and ID depend on the line or the data: see `_placeholders`).
PLACEHOLDERS = {
    "W": "1",  # --workers W: one worker (2-core CI)
    "K": "2",  # --shard-size K: two scenarios a shard, so the 4 scenarios make two shards
    "IN": "shards/",  # build-sdc-paths IN: the synthetic shards
    "OUT": "sdc_shards/",
    "MORE": "synthetic-knob_shards/",  # validate shards/ [MORE ...]: the second synthetic conversion
    "RUN_DIR": "runs/readme",  # the run the first `vmax-sim train` line writes (with --out runs/readme)
    "RUN": "runs/readme",
    "ADDR": None,  # --address ADDR needs a Ray cluster: that choice is left out
}
# Substitutions that keep the run short, (pattern, replacement) on the expanded command, with the reason.
SHORTER = [
    # 200 synthetic scenarios take minutes to generate and enrich; 4 exercise the same code
    (r"--num-scenarios 200\b", "--num-scenarios 4"),
    # one bench configuration, few steps (the full bench runs for many minutes)
    (r"^vmax-sim bench\b", "vmax-sim bench --batch-sizes 1 --steps 5 --env minimal"),
    # one training configuration, one chunk, with the tiny settings below; the script is the checkout's (the
    # README runs it from the checkout, this test from a temporary folder)
    (r"^python benchmarks/training.py$", f"python {REPO}/benchmarks/training.py --only bc-mlp --chunks 1 {{TINY}}"),
    # a one-hour budget: the tiny step count ends the run first
    (r"train\.max_wall_minutes=60", "train.max_wall_minutes=60 {TINY}"),
    # section.field=value ...: the overrides that make a run take seconds (tests/training/conftest.py)
    (r"section\.field=value", "{TINY}"),
]
TINY = ("train.total_env_steps=20 train.chunk_steps=5 train.pool_size=4 train.pool_refresh=2 "
        "train.eval_scenarios=4 train.eval_batch_size=4 train.eval_every=0 train.checkpoint_every=10 "
        "data.num_objects=16 data.num_roadgraph_points=5000 data.num_paths=4 data.max_num_lights=8 "
        "data.synthetic_train_scenarios=4 data.synthetic_eval_scenarios=4 algo_preset=debug "
        "network.embed_dim=16 network.output_dim=32 network.mlp_hidden=32 "
        "obs.num_objects=4 obs.num_history=2 obs.num_path_targets=4")
# Options left out of the commands, with the reason (the rest of the line still runs).
LEFT_OUT = {
    "--serve": "blocks until Ctrl-C: run apart by `_serve_once`",
}


def command_block() -> list[str]:
    """The README's shell lines after the two install blocks, comments stripped."""
    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(), re.DOTALL)
    assert len(blocks) >= 3, "the README lost its install blocks or its command block"
    lines = [line.split(" #")[0].strip() for block in blocks[2:] for line in block.splitlines()]
    return [line for line in lines if line]


def _choices(group: str) -> list[str]:
    """`a|b` or `{a,b}` -> its alternatives; anything else is one choice."""
    if "|" in group:
        return group.split("|")
    return [group]


def _continued(previous: str) -> str:
    """The previous line's arguments as `...` repeats them: optional groups included except alternatives
    (`[--resume|--overwrite]`), the first of each `{a,b}` choice, its --out a new folder (the old one holds a
    conversion of other settings, which convert refuses)."""
    arguments = " ".join(previous.split()[2:])
    arguments = re.sub(r"\[[^\]]*\|[^\]]*\]", "", arguments)
    arguments = re.sub(r"\[([^\]]*)\]", r"\1", arguments)
    return re.sub(r"\{([^,}]*)[^}]*\}", r"\1", arguments)


def expand(line: str, previous: str) -> list[str]:
    """A synopsis line -> the concrete commands: optional groups included, one command per choice.
    `...` as an argument stands for the previous line's (`_continued`); inside a group it is dropped."""
    words = line.split()
    if "..." in words:
        at = words.index("...")
        new_out = f"{words[at + 1].lstrip('-')}_shards/" if at + 1 < len(words) else "more_shards/"
        repeated = re.sub(r"--out \S+", f"--out {new_out}", _continued(previous)).split()
        line = " ".join(words[:at] + _without_given(repeated, words) + words[at + 1:])
    line = re.sub(r" \.\.\.(?=\])", "", line)
    parts = re.split(r"(\[[^\]]*\]|\{[^}]*\})", line)
    options = []
    for part in parts:
        if part.startswith("["):
            options.append(_choices(part[1:-1]))
        elif part.startswith("{"):
            options.append(part[1:-1].split(","))
        else:
            options.append([part])
    return [re.sub(r"\s+", " ", "".join(choice)).strip() for choice in itertools.product(*options)]


def _without_given(repeated: list[str], words: list[str]) -> list[str]:
    """Drops the repeated options (with their value) that the line gives itself (`--dataset synthetic ...`)."""
    kept, skip = [], False
    for index, word in enumerate(repeated):
        if skip:
            skip = False
            continue
        if word.startswith("--") and word in words:
            skip = index + 1 < len(repeated) and not repeated[index + 1].startswith("--")
            continue
        kept.append(word)
    return kept


def concrete(command: str, placeholders: dict) -> str:
    """Placeholders replaced and the SHORTER substitutions applied; a LEFT_OUT option, or an option whose
    placeholder is None, is dropped (the rest of the command still runs)."""
    swapped = []
    for word in command.split():
        value = placeholders.get(word, word)
        if word in LEFT_OUT:
            continue
        if value is None:
            swapped.pop()  # the option the placeholder belongs to
            continue
        swapped.append(value)
    command = " ".join(swapped)
    for pattern, replacement in SHORTER:
        command = re.sub(pattern, replacement, command)
    return command.replace("{TINY}", TINY)


def test_the_synopsis_expands_as_a_user_reads_it():
    assert expand("a b [--x X] [--r|--o]", "") == ["a b --x X --r", "a b --x X --o"]
    assert expand("a b --d {p,q} --s RAW", "") == ["a b --d p --s RAW", "a b --d q --s RAW"]
    assert expand("a c --d s ... --k v", "a c --d s --n {2,3} --out o/ [--w W] [--r|--o]") == [
        "a c --d s --n 2 --out k_shards/ --w W --k v"]
    assert expand("a v s/ [MORE ...]", "") == ["a v s/ MORE"]
    assert concrete("x y --serve", PLACEHOLDERS) == "x y"
    assert concrete("x y --engine ray --address ADDR", PLACEHOLDERS) == "x y --engine ray"


def test_the_readme_command_block_is_what_this_test_expands():
    lines = command_block()
    assert any(line.startswith("scenariomax convert --dataset synthetic") for line in lines)
    assert any(line.startswith("vmax-sim evaluate") for line in lines)
    assert all(line.split()[0] in ("scenariomax", "vmax-sim", "python") for line in lines), lines


def _placeholders(line: str, tmp: Path) -> dict:
    """PLACEHOLDERS plus the ones that depend on the data: RAW -> the real recording of the line's dataset,
    ID -> the first scenario of shards/. Real-data conversions write to shards/<dataset>/ (the README's
    `--out shards/` holds the synthetic conversion by then; `shards/womd` is the folder the mixture line reads)."""
    found = dict(PLACEHOLDERS)
    dataset = re.search(r"--dataset (\w+)", line)
    if dataset and dataset.group(1) != "synthetic":
        found["RAW"] = str(REALDATA / dataset.group(1))
        found["shards/"] = f"shards/{dataset.group(1)}/"
    if (tmp / "shards").is_dir() and "ID" in line.split():
        import scenariomax

        found["ID"] = next(iter(scenariomax.read_shards(str(tmp / "shards")))).scenario_id
    return found


def _environment(tmp: Path) -> dict:
    """PATH with the virtualenv's scripts, the caches in tmp, nuPlan's variables on a generated log and map."""
    from tests.sources.nuplan.builders import write_fixture

    nuplan = write_fixture(tmp / "nuplan")
    return {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}", "VMAX_CACHE_DIR": str(tmp / "cache"),
            "NUPLAN_DB_FILES": str(nuplan.db_path), "NUPLAN_MAPS_ROOT": str(nuplan.maps_root),
            "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"}


def _serve_once(tmp: Path, env: dict) -> None:
    """`scenariomax view shards/ --serve` (port 0: any free one): the page answers, Ctrl-C stops it cleanly."""
    # SIGINT back to its default in the child: a test run started in the background (`pytest &`) inherits it
    # ignored, and Python keeps an ignored SIGINT ignored, so Ctrl-C would never reach the server
    server = subprocess.Popen(["scenariomax", "view", "shards/", "--serve", "--port", "0"], cwd=tmp, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        line = server.stdout.readline()
        url = re.search(r"http://\S+/", line)
        assert url, f"--serve printed no address: {line!r} {server.stderr.read() if server.poll() else ''}"
        with urllib.request.urlopen(url.group(0), timeout=30) as page:
            assert page.status == 200
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)


def _runnable(line: str) -> str | None:
    """Why a whole line cannot run here, or None."""
    if "--engine ray" in line:
        try:
            import ray  # noqa: F401
        except ImportError:
            return "ray is not installed (the `ray` extra)"
    if "RAW" in line.split() and not REALDATA.is_dir():
        return f"{REALDATA} is absent"
    return None


@pytest.mark.slow  # ~30 commands, each a fresh process with JAX to import and a program to compile (~10 min)
def test_every_readme_shell_line_runs(tmp_path):
    env = _environment(tmp_path)
    previous, ran, skipped = "", [], []
    for line in command_block():
        reason = _runnable(line)
        if reason:
            skipped.append(f"{line}: {reason}")
            previous = line
            continue
        for command in expand(line, previous):
            command = concrete(command, _placeholders(command, tmp_path))
            if command.startswith("vmax-sim train") and "--resume" not in command and "runs/readme" not in str(ran):
                command += " --out runs/readme"  # RUN_DIR: the later lines' run (the default name has the time)
            argv = shlex.split(command)
            argv[0] = sys.executable if argv[0] == "python" else argv[0]
            done = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
            assert done.returncode == 0, (f"README line `{line}` as `{command}` failed ({done.returncode}):\n"
                                          f"{done.stdout[-1500:]}\n{done.stderr[-3000:]}")
            assert "Traceback" not in done.stderr, f"`{command}`:\n{done.stderr[-3000:]}"
            ran.append(command)
        previous = line
    _serve_once(tmp_path, env)
    for written in ("shards/manifest.json", "synthetic-knob_shards/manifest.json", "sdc_shards/manifest.json",
                    "scene.png", "docs/schema.md", "view.html", "rollouts.html", "runs/readme/summary.json"):
        assert (tmp_path / written).exists(), f"{written} was not written by the README's commands"
    print("\n".join(["ran:", *ran, "skipped:", *skipped]))
    shutil.rmtree(tmp_path / "cache", ignore_errors=True)
