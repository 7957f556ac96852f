import subprocess
import sys

MODULES = ["scenariomax", "scenariomax.pipeline", "scenariomax.inspect", "scenariomax.validate",
           "scenariomax.render", "scenariomax.enrich", "scenariomax.sources.synthetic", "scenariomax.sources.womd",
           "scenariomax.sources.av2", "scenariomax.sources.nuplan", "scenariomax.sources.scenarionet",
           "cli.scenariomax_cli"]


def test_scenariomax_never_imports_jax_or_tensorflow():
    code = ("import sys\n" + "".join(f"import {m}\n" for m in MODULES) +
            "bad = [m for m in ('jax', 'tensorflow', 'ray', 'torch') if m in sys.modules]\n"
            "print(','.join(bad))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"scenariomax imported {out} at import time"
