"""The restricted unpickler: malicious pickles are refused and nothing in them runs."""

from __future__ import annotations

import builtins
import collections
import os
import pickle
import pickletools

import numpy as np
import pytest

from scenariomax.errors import InputError
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


class Reduces:
    """Pickles as `func(*args)` (plus `state` for BUILD): hand-made pickles without writing opcodes."""

    def __init__(self, func, args, state=None):
        self.func, self.args, self.state = func, args, state

    def __reduce__(self):
        return (self.func, self.args) if self.state is None else (self.func, self.args, self.state)


@pytest.mark.parametrize("factory", [list, dict, int, float, str, set, tuple, None])
@pytest.mark.parametrize("protocol", [2, 4, 5])
def test_defaultdict_with_a_plain_factory_loads(factory, protocol):
    value = collections.defaultdict(factory, {"a": factory() if factory else 1})
    loaded = loads_restricted(pickle.dumps({"summary": value}, protocol=protocol))["summary"]
    assert isinstance(loaded, collections.defaultdict) and loaded.default_factory is factory
    assert dict(loaded) == dict(value)


def test_defaultdict_with_os_system_factory_is_refused(tmp_path):
    marker = tmp_path / "marker"
    desc = build_description()
    desc["metadata"]["summary"] = collections.defaultdict(os.system, {f"touch {marker}": 1})
    path = tmp_path / "sd_evil.pkl"
    path.write_bytes(pickle.dumps(desc, protocol=4))
    with pytest.raises(InputError, match=r"refused pickle global (posix|nt)\.system"):
        list(ScenarioNetSource(str(path)).read_unit(str(path)))
    assert not marker.exists()


@pytest.mark.parametrize("factory", [np.dtype, collections.OrderedDict, frozenset, complex])
def test_defaultdict_with_an_allowed_but_callable_factory_is_refused(factory):
    with pytest.raises(RefusedGlobalError, match="defaultdict with factory"):
        loads_restricted(pickle.dumps(collections.defaultdict(factory), protocol=4))


@pytest.mark.parametrize("payload, refused", [
    (Reduces(int, ("5",)), "builtins.int called"),
    (Reduces(np.ndarray, ((10 ** 12,),)), "numpy.ndarray"),  # would allocate uninitialised memory
    (Reduces(__import__("codecs").encode, ("x", "zlib")), "_codecs.encode"),
    (Reduces(np.dtype, ([("a", "f8")] * 3,)), "numpy.dtype of a list"),
    (Reduces(collections.defaultdict, (list, {"a": 1})), "more than a factory"),
])
def test_allowed_globals_check_their_arguments(payload, refused):
    with pytest.raises(RefusedGlobalError, match=refused):
        loads_restricted(pickle.dumps(payload, protocol=4))


@pytest.mark.parametrize("data, opcode", [
    (b"\x80\x02c__builtin__\nset\n)\x81.", "NEWOBJ"),  # set.__new__(set): building instances is not allowed
    (b"\x80\x02}}b.", "BUILD"),  # state of a dict
    (b"\x80\x02(c__builtin__\nset\no.", "OBJ"),
])
def test_instance_opcodes_are_refused(data, opcode):
    with pytest.raises(RefusedGlobalError, match=opcode):
        loads_restricted(data)


def test_python2_style_pickle_loads():
    value = {"b": b"\x00\xff", "arr": np.arange(3, dtype=np.int16), "ba": bytearray(b"xy"), "c": 1 + 2j,
             "s": slice(1, 5, 2), "fs": frozenset({"a"})}
    loaded = loads_restricted(pickle.dumps(value, protocol=2))
    assert loaded["b"] == value["b"] and loaded["arr"].tolist() == [0, 1, 2] and loaded["ba"] == bytearray(b"xy")
    assert loaded["c"] == 1 + 2j and loaded["s"] == slice(1, 5, 2) and loaded["fs"] == frozenset({"a"})


def test_forged_dtype_state_cannot_change_numpy():
    """numpy.dtype('f8', copy=False) is the process-wide float64 descriptor: a BUILD on it with forged
    flags used to corrupt numpy for the rest of the run. The stand-in always copies, and BUILD gets
    the state numpy itself writes."""
    forged = Reduces(np.dtype, ("f8", False, False), (3, "<", None, None, None, -1, -1, 63))
    loaded = loads_restricted(pickle.dumps([forged], protocol=4))[0]
    assert loaded == np.dtype("f8") and loaded.flags == 0 and np.dtype("f8").flags == 0
    assert loads_restricted(pickle.dumps(np.dtype(">i4"), protocol=4)) == np.dtype(">i4")
    np.testing.assert_array_equal(np.zeros(3) + 1, [1, 1, 1])


@pytest.mark.parametrize("value", [np.zeros(2, dtype=[("a", "f8"), ("b", "i4")]), np.zeros(2, dtype="M8[s]"),
                                   np.dtype(("f8", (3,)))])
def test_structured_and_datetime_dtypes_are_refused(value):
    with pytest.raises(RefusedGlobalError, match="only plain dtypes"):
        loads_restricted(pickle.dumps(value, protocol=4))


def test_build_only_fills_new_objects():
    array = Reduces(np.asarray, ([1.0],))  # not an allowed global: refused before numpy sees it
    with pytest.raises(RefusedGlobalError):
        loads_restricted(pickle.dumps(array, protocol=4))
    # The array's own pickle, then "fetch the array from the memo and BUILD it again".
    data = pickle.dumps(np.arange(3.0), protocol=2)
    ops = list(pickletools.genops(data))
    reduce_at = next(i for i, (op, _, _) in enumerate(ops)  # the _reconstruct call, its state follows
                     if op.name == "REDUCE" and ops[i + 2][0].name == "MARK")
    memo_index, state_from = ops[reduce_at + 1][1], ops[reduce_at + 2][2]
    build_at = [pos for op, _, pos in ops if op.name == "BUILD"][-1]  # the array's (the dtype's comes first)
    again = data[:build_at + 1] + b"h" + bytes([memo_index]) + data[state_from:build_at] + b"b."
    with pytest.raises(RefusedGlobalError, match="not a new array or dtype"):
        loads_restricted(again)
    assert loads_restricted(data).tolist() == [0.0, 1.0, 2.0]


def test_bytearray_length_is_checked_before_allocating():
    # BYTEARRAY8 announcing 2**40 bytes in a 20-byte pickle: the stock unpickler allocates first.
    data = b"\x80\x05\x96" + (1 << 40).to_bytes(8, "little") + b"abc."
    with pytest.raises(pickle.UnpicklingError, match="bytearray of"):
        loads_restricted(data)
    assert loads_restricted(pickle.dumps(bytearray(b"abc"), protocol=5)) == bytearray(b"abc")


class ReconstructsFromAnArray:
    """Pickles as numpy's `_reconstruct` called with an array where the ndarray class belongs (as a corrupted
    stream can put any object there): the refusal must not print the array, whose repr spans many lines."""

    def __reduce__(self):
        reconstruct = np.zeros(1).__reduce__()[0]  # numpy._core (or numpy.core) .multiarray._reconstruct
        return reconstruct, (np.zeros((40, 3)), (0,), b"b")


def test_refusals_of_corrupted_names_and_arguments_stay_on_one_line(tmp_path):
    # A global whose name holds a newline (a corrupted byte in the stream), and an array passed as a class.
    name_with_newline = (b"\x80\x04\x8c\x13numpy._core.numeric\x94\x8c\x0c_frombuff\ner\x94\x93\x94.")
    for data, shown in ((name_with_newline, "numpy._core.numeric._frombuff\\ner"),
                        (pickle.dumps(ReconstructsFromAnArray(), protocol=4), "_reconstruct of a ndarray")):
        path = tmp_path / "sd_corrupted.pkl"
        path.write_bytes(data)
        with pytest.raises(InputError) as caught:
            load_pickle(path)
        message = str(caught.value)
        assert "\n" not in message and str(path) in message and shown in message, message
