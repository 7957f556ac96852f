"""Conversion workers keep freed memory for the next scenario (scenariomax._allocator)."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Allocates eight 2 MB blocks and frees them, 50 times, and prints the page faults it took (a scenario's arrays and
# record, roughly). glibc's defaults give the 16 MB back to the system each time (its trim threshold adapts only up to
# twice the largest block freed) and fault it in again; a heap that keeps freed memory faults it in once.
_FAULTS = textwrap.dedent("""
    import resource, sys
    from scenariomax._allocator import keep_freed_memory
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.schema import Sizes
    from tests.foundation.toy_source import ToySource
    if sys.argv[1] == "convert":  # tuned by the conversion itself, as a worker is
        convert(ToySource(), ConvertSettings(out=sys.argv[2], sizes=Sizes(num_objects=8, num_roadgraph=2000,
                num_lanes=4), shard_size=5, progress=False, workers=1))
        assert keep_freed_memory.cache_info().currsize == 1
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(50):
        blocks = [bytearray(2 << 20) for _ in range(8)]
        del blocks
    print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults)
""")


def _faults(mode: str, out: Path) -> int:
    done = subprocess.run([sys.executable, "-c", _FAULTS, mode, str(out)], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return int(done.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the allocator is tuned on Linux (glibc) only")
def test_a_conversion_keeps_freed_blocks_instead_of_faulting_them_in_again(tmp_path):
    from scenariomax._allocator import keep_freed_memory

    if not keep_freed_memory():
        pytest.skip("this libc has no mallopt (not glibc)")
    untuned, tuned = _faults("plain", tmp_path / "a"), _faults("convert", tmp_path / "b")
    assert untuned > 50 * 2000  # 16 MB paged in again each time (4096 pages of 4 KB)
    assert tuned < untuned / 20
