"""`WomdSource`: the pipeline's view of WOMD TFRecord files (Scenario protos or motion tf.Examples)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator

from scenariomax.errors import InputError
from scenariomax.io.tfrecord import RecordError, iter_records
from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure, UnitItem, expand_inputs
from scenariomax.sources.womd.convert import (
    SOURCE_NAME,
    ScenarioBuildError,
    parse_raw_scenario,
    parse_scenario,
    scenario_windows,
)
from scenariomax.sources.womd.sdc_paths import SDC_PATHS_AUTO, SDC_PATHS_MODES
from scenariomax.sources.womd.tfexample import (
    FORMAT_AUTO,
    FORMAT_SCENARIO,
    FORMAT_TF_EXAMPLE,
    looks_like_tf_example,
    tf_example_to_scenario,
)
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE

FILE_PATTERN = "*tfrecord*"
_FORMATS = (FORMAT_AUTO, FORMAT_SCENARIO, FORMAT_TF_EXAMPLE)


def expand_src(src: str, pattern: str) -> list[str]:
    """Sorted input files from a file, a directory (searched recursively for `pattern`) or a glob."""
    return expand_inputs(src, pattern, "WOMD record files")


def one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    user_facing = (ScenarioBuildError, InputError, RecordError)  # their message already says what is wrong
    return text if isinstance(error, user_facing) else f"{type(error).__name__}: {text}"


@dataclasses.dataclass(frozen=True)
class WomdSource:
    """WOMD TFRecord files. `womd_format`: "auto" (detected per file from its first record),
    "scenario" (Scenario protos) or "tf_example" (motion tf.Examples). `sdc_paths`: "auto" (Waymo's
    own paths when a Scenario proto carries them, else reconstructed), "waymo" or "reconstruct"."""

    src: str
    sizes: Sizes | None = None
    womd_format: str = FORMAT_AUTO
    window_stride: int = DEFAULT_WINDOW_STRIDE
    sdc_paths: str = SDC_PATHS_AUTO
    # road edges turned road-on-the-left while reading; off when the enrichment follows, which orients them on the
    # resampled roadgraph anyway (~15% of a conversion done once instead of twice). The same votes decide, except for
    # an edge left with no lane in sight by the budget's crop: the source saw the whole map, the enrichment keeps it
    # as written (every real sample converts to the same bytes either way)
    orient_edges: bool = True
    name: str = SOURCE_NAME

    def __post_init__(self) -> None:
        if self.womd_format not in _FORMATS:
            raise ValueError(f"womd_format must be one of {_FORMATS}, got {self.womd_format!r}")
        if self.sdc_paths not in SDC_PATHS_MODES:
            raise ValueError(f"sdc_paths must be one of {SDC_PATHS_MODES}, got {self.sdc_paths!r}")
        if self.window_stride <= 0:
            raise ValueError(f"window_stride must be positive, got {self.window_stride}")

    @property
    def budget(self) -> Sizes:
        return self.sizes or Sizes()

    def list_units(self) -> list[str]:
        return expand_src(self.src, FILE_PATTERN)

    def settings(self) -> dict:
        return {"womd_format": self.womd_format, "window_stride": self.window_stride,
                "sdc_paths": self.sdc_paths, "orient_edges": self.orient_edges,
                "sizes": self.budget.as_dict()}

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        if not os.path.isfile(unit):
            raise InputError(f"{unit}: no such file")
        fmt = self.womd_format
        try:
            for index, record in enumerate(iter_records(unit)):
                if fmt == FORMAT_AUTO:
                    fmt = FORMAT_TF_EXAMPLE if looks_like_tf_example(record) else FORMAT_SCENARIO
                yield from self._convert_record(unit, index, record, fmt)
        except RecordError as error:
            raise InputError(one_line(error)) from None
        except OSError as error:
            raise InputError(f"{unit}: cannot read ({error.strerror or error})") from None

    def _convert_record(self, unit: str, index: int, record: bytes, fmt: str) -> Iterator[UnitItem]:
        ref = f"record {index}"
        try:
            if fmt == FORMAT_TF_EXAMPLE:
                yield tf_example_to_scenario(record, self.budget)
                return
            message = parse_scenario(record, bulk=True)
            ref = message.scenario_id or ref
            for item in scenario_windows(message, self.budget, self.window_stride, self.sdc_paths,
                                         self.orient_edges, parse_raw_scenario(record)):
                yield Failure(unit, ref, one_line(item)) if isinstance(item, Exception) else item
        except Exception as error:  # noqa: BLE001 - fault isolation: one bad scenario never stops the file
            yield Failure(unit, ref, one_line(error))
