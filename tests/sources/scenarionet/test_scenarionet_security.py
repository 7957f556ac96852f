"""The restricted unpickler: malicious pickles are refused and nothing in them runs."""

from __future__ import annotations

import builtins
import collections
import os
import pickle

import numpy as np
import pytest

from scenariomax.sources.base import InputError
from scenariomax.sources.scenarionet import (
    RefusedGlobalError,
    ScenarioNetSource,
    load_pickle,
    loads_restricted,
)
from tests.sources.scenarionet.fixtures import build_description


class CallsOsSystem:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


class CallsExec:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return builtins.exec, (f"open({str(self.marker)!r}, 'w').write('pwned')",)


@pytest.mark.parametrize("payload_cls, refused", [(CallsOsSystem, "system"), (CallsExec, "builtins.exec")])
def test_malicious_pickle_is_refused_and_never_runs(tmp_path, payload_cls, refused):
    marker = tmp_path / "marker"
    desc = build_description()
    desc["metadata"]["evil"] = payload_cls(marker)  # hidden deep inside an otherwise valid file
    path = tmp_path / "sd_evil.pkl"
    path.write_bytes(pickle.dumps(desc, protocol=4))
    with pytest.raises(InputError) as info:
        list(ScenarioNetSource(str(path)).read_unit(str(path)))
    message = str(info.value)
    assert str(path) in message and "refused pickle global" in message and refused in message
    assert "\n" not in message
    assert not marker.exists()


def test_other_globals_are_refused():
    with pytest.raises(RefusedGlobalError, match="collections.Counter"):
        loads_restricted(pickle.dumps(collections.Counter(a=1)))


def test_plain_containers_and_arrays_load():
    value = {"a": [1, 2.5, "s", None, (1, 2)], "b": np.arange(6, dtype=np.float32).reshape(2, 3),
             "c": np.float64(1.5), "d": {1, 2}, "e": collections.OrderedDict(x=1), "f": np.array(["x", "y"])}
    for protocol in (2, 4, 5):
        loaded = loads_restricted(pickle.dumps(value, protocol=protocol))
        np.testing.assert_array_equal(loaded["b"], value["b"])
        assert loaded["a"] == value["a"] and loaded["c"] == 1.5 and loaded["d"] == {1, 2}
        assert loaded["e"] == {"x": 1} and loaded["f"].tolist() == ["x", "y"]


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        load_pickle(tmp_path / "nope.pkl")
