import subprocess
import sys

MODULES = ["scenariomax", "scenariomax.pipeline", "scenariomax.inspect", "scenariomax.validate",
           "scenariomax.render", "scenariomax.enrich", "scenariomax.sources.synthetic", "scenariomax.sources.womd",
           "scenariomax.sources.av2", "scenariomax.sources.nuplan", "scenariomax.sources.scenarionet",
           "vmax_cli.scenariomax_cli"]


def test_scenariomax_never_imports_jax_or_tensorflow():
    code = ("import sys\n" + "".join(f"import {m}\n" for m in MODULES) +
            "bad = [m for m in ('jax', 'tensorflow', 'ray', 'torch') if m in sys.modules]\n"
            "print(','.join(bad))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"scenariomax imported {out} at import time"


def test_scenariomax_commands_run_without_jax(tmp_path):
    """convert, validate, inspect --render and view work in a process where importing JAX fails (the base install
    has no JAX): the commands' lazy imports stay on the numpy side too."""
    shards, picture, page = tmp_path / "shards", tmp_path / "scene.png", tmp_path / "view.html"
    commands = [["convert", "--dataset", "synthetic", "--num-scenarios", "2", "--num-objects", "16",
                 "--roadgraph-points", "2000", "--workers", "1", "--out", str(shards)],
                ["validate", str(shards)], ["inspect", str(shards), "--render", str(picture)],
                ["view", str(shards), "--out", str(page)]]
    code = ("import sys\n"
            "for blocked in ('jax', 'jaxlib', 'flax', 'tensorflow', 'torch'):\n"
            "    sys.modules[blocked] = None  # any import of it raises ImportError\n"
            "from vmax_cli.scenariomax_cli import main\n"
            f"for args in {commands!r}:\n"
            "    try:\n"
            "        main(args, standalone_mode=False)\n"
            "    except SystemExit as done:  # convert ends with sys.exit(its status)\n"
            "        assert done.code in (0, None), (args, done.code)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert picture.stat().st_size > 1000 and page.stat().st_size > 1000
