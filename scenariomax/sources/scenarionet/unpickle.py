"""A restricted unpickler for ScenarioNet `.pkl` files, which are untrusted, executable input.

Only the globals needed to rebuild plain containers and numpy arrays are allowed; any other global
(os.system, builtins.exec, a class from some package...) is refused before it is ever looked up,
so nothing from the file is executed. Even the allowed globals are stand-ins that check their
arguments (`numpy.ndarray` cannot be called, a `defaultdict` factory must be a plain builtin type; an
old MetaDrive enum class named by the file only turns one of its values into an `EnumValue`).

A pickle is also a compression format: a few bytes can ask for a huge array, or reference one
array thousands of times. `PickleLimits` caps both what unpickling may build (opcodes run, bytes
built by calls) and what the result expands to when every shared reference is counted again,
which is what the converter would materialise.

We run the standard library's pure-Python unpickler (`pickle._Unpickler`), not the C one, because
only it lets us see each opcode (BUILD in particular) before it runs; real files cost ~50 ms more.
"""

from __future__ import annotations

import codecs
import collections
import dataclasses
import io
import math
import os
import pickle
import struct

import numpy as np

_core = np._core if hasattr(np, "_core") else np.core  # numpy 2 vs 1
_multiarray = _core.multiarray

_POINTER_BYTES = 64  # rough cost of one element of a set / dict built by a call


class RefusedGlobalError(pickle.UnpicklingError):
    """The pickle asked for a global (or a use of one) outside the allow-list."""


class PickleLimitError(pickle.UnpicklingError):
    """The pickle builds, or expands to, more than `PickleLimits` allows."""


@dataclasses.dataclass(frozen=True)
class PickleLimits:
    """Caps on one pickle (None switches a cap off).

    max_file_bytes: size of the file itself.
    max_opcodes: pickle opcodes run; every object the unpickler makes costs at least one.
    max_built_bytes: bytes built by allowed calls and array states while unpickling (a shared
        input is charged on every call).
    max_nodes / max_data_bytes: values in the result and their array/str/bytes payload, counting a
        shared value once per reference (memo-sharing makes a small file expand to a large tree).
    max_depth: nesting of the result (deep trees break recursive consumers)."""

    max_file_bytes: int | None = 512 << 20
    max_opcodes: int | None = 20_000_000
    max_built_bytes: int | None = 512 << 20
    max_nodes: int | None = 16_000_000
    max_data_bytes: int | None = 256 << 20
    max_depth: int | None = 100


SCENARIO_LIMITS = PickleLimits()
# dataset_summary.pkl / dataset_mapping.pkl of a large database can be big; we only read their keys
# and relative folders, so the expansion caps are off (the build caps still hold).
INDEX_LIMITS = PickleLimits(max_file_bytes=8 << 30, max_opcodes=None, max_built_bytes=1 << 30, max_nodes=None,
                            max_data_bytes=None, max_depth=None)

# Enum classes MetaDrive's 2021-2022 Waymo converter (`waymo_utils.py`, earlier `waymo_map_utils.py`) put in
# its pickles, with the values each has (those of the WOMD protos: Track.ObjectType, RoadLine.RoadLineType,
# RoadEdge.RoadEdgeType). Run as a script, it named them `__main__.<class>`; imported, by its module path.
WRITER_ENUMS: dict[str, range] = {"AgentType": range(5), "RoadLineType": range(9), "RoadEdgeType": range(3)}
_WRITER_ENUM_MODULES = ("metadrive.utils.waymo_map_utils", "metadrive.utils.waymo_utils.waymo_utils",
                        "metadrive.utils.waymo_utils.utils")

# Globals a ScenarioNet pickle may name, and why (numpy 1 spells its core `numpy.core`, numpy 2
# `numpy._core`; protocol <= 2 spells builtins `__builtin__`).
_NUMPY_CORES = ("numpy.core", "numpy._core")
ALLOWED_GLOBALS: dict[tuple[str, str], str] = {
    **{(f"{core}.multiarray", "_reconstruct"): "empty ndarray, filled by BUILD" for core in _NUMPY_CORES},
    **{(f"{core}.multiarray", "scalar"): "numpy scalar" for core in _NUMPY_CORES},
    **{(f"{core}.numeric", "_frombuffer"): "ndarray in protocol 5" for core in _NUMPY_CORES},
    ("numpy", "ndarray"): "argument of _reconstruct only",
    ("numpy", "dtype"): "array dtype",
    ("collections", "OrderedDict"): "container",
    ("collections", "defaultdict"): "container (factory: list, dict, int, float, str, set, tuple or None)",
    ("_codecs", "encode"): "bytes in protocol 2 (str -> latin-1 only)",
    **{(module, name): "container / value" for module in ("builtins", "__builtin__")
       for name in ("set", "frozenset", "complex", "slice", "bytearray")},
    **{(module, name): "defaultdict factory only" for module in ("builtins", "__builtin__")
       for name in ("list", "dict", "int", "float", "str", "tuple")},
    ("metadrive.scenario.scenario_description", "ScenarioDescription"):
        "a dict subclass (MetaDrive, March 2023): NEWOBJ with no arguments builds a plain dict",
    **{(module, name): f"an enum member (MetaDrive 2021-2022): `{name}(value)` gives an EnumValue, nothing imported"
       for module in ("__main__", *_WRITER_ENUM_MODULES) for name in WRITER_ENUMS},
    ("__builtin__", "long"): "defaultdict factory only (Python 3's int in protocol <= 2)",
    ("__builtin__", "unicode"): "defaultdict factory only (Python 3's str in protocol <= 2)",
}
_FACTORY_NAMES = frozenset({"list", "dict", "int", "float", "str", "set", "tuple", "long", "unicode"})


def _shown(value) -> str:
    """A short one-line name of a value a (possibly corrupted) pickle handed us: a string's repr (its control
    characters escaped) cut to 60 characters, a stand-in's own name, else the type's name (the repr of an
    array or a dict would span many lines)."""
    if isinstance(value, str):
        text = repr(value)
        return text if len(text) <= 60 else text[:56] + "...'"
    if isinstance(value, (_Builtin, _DictClass, _EnumClass)):
        return repr(value)
    return f"a {type(value).__name__}"


def _refuse(what: str) -> RefusedGlobalError:
    # One line whatever a corrupted stream put into the names: control characters escaped, the length capped.
    what = what.encode("unicode_escape").decode("ascii")
    what = what if len(what) <= 200 else what[:197] + "..."
    return RefusedGlobalError(f"refused pickle global {what} (only plain containers and numpy arrays are allowed)")


class _Builtin:
    """Stand-in for a builtin type named by the pickle: callable only where `call` allows it."""

    __slots__ = ("name", "type", "call")

    def __init__(self, name: str, type_: type, call=None):
        self.name, self.type, self.call = name, type_, call

    def __call__(self, *args):
        if self.call is None:
            raise _refuse(f"builtins.{self.name} called (allowed only as a defaultdict factory)")
        return self.call(*args)

    def __repr__(self) -> str:
        return f"<builtin {self.name}>"


_NDARRAY = _Builtin("numpy.ndarray", np.ndarray)  # only ever an argument of _reconstruct


class _DictClass:
    """Stand-in for a writer's dict subclass: NEWOBJ of it with no arguments gives a plain dict (its
    items follow as SETITEMS), and it cannot be called or used any other way."""

    __slots__ = ("name",)

    def __init__(self, name: str):
        self.name = name

    def __repr__(self) -> str:
        return f"<dict class {self.name}>"


_DICT_CLASSES = {("metadrive.scenario.scenario_description", "ScenarioDescription")}


@dataclasses.dataclass(frozen=True, slots=True)
class EnumValue:
    """A member of one of an old writer's enum classes (`WRITER_ENUMS`), as the pickle named it: the class's
    name and the member's value. The class itself is never imported; the converter maps the value."""

    enum: str
    value: int


class _EnumClass:
    """Stand-in for a writer's enum class: an Enum member pickles as a call of its class with its value
    (GLOBAL, the value, REDUCE), so calling this with one of the class's values gives an `EnumValue`."""

    __slots__ = ("module", "name", "values", "charge")

    def __init__(self, module: str, name: str, charge):
        self.module, self.name, self.values, self.charge = module, name, WRITER_ENUMS[name], charge

    def __call__(self, *args):
        value = args[0] if len(args) == 1 else None
        if type(value) is not int or value not in self.values:
            shown = ", ".join(repr(a)[:20] for a in args)
            raise _refuse(f"{self.module}.{self.name} called with ({shown}) (only one of its values "
                          f"{self.values.start}-{self.values.stop - 1})")
        self.charge(_POINTER_BYTES, "enum member")
        return EnumValue(self.name, value)

    def __repr__(self) -> str:
        return f"<enum class {self.module}.{self.name}>"


def _sized(value, what: str) -> int:
    if not isinstance(value, (list, tuple, set, frozenset, dict)):
        raise _refuse(f"{what} called with a {type(value).__name__}")
    return len(value)


def _small_dtype(spec) -> np.dtype:
    """A dtype given as a dtype or a short string: a long field list could itself be large."""
    if isinstance(spec, np.dtype):
        return spec
    if isinstance(spec, (str, bytes)) and len(spec) <= 64:
        return np.dtype(spec)
    raise _refuse(f"numpy dtype from a {type(spec).__name__}")


def _shape_bytes(shape, dtype) -> int:
    """Bytes an array of `shape` and `dtype` needs, in Python ints (no overflow, no allocation)."""
    if not isinstance(shape, tuple) or not all(isinstance(d, int) and d >= 0 for d in shape):
        raise pickle.UnpicklingError(f"bad array shape {shape!r}")
    return math.prod(shape) * np.dtype(dtype).itemsize


class _Charges:
    """Running total of what allowed calls build; raises PickleLimitError past the cap."""

    def __init__(self, limit: int | None):
        self.limit, self.used = limit, 0

    def __call__(self, nbytes: int, what: str) -> None:
        self.used += int(nbytes)
        if self.limit is not None and self.used > self.limit:
            raise PickleLimitError(f"builds more than {self.limit} bytes while unpickling ({what})")


def _checked_globals(charge: _Charges, unbuilt: dict[int, object]) -> dict[tuple[str, str], object]:
    """The objects `find_class` hands out, each checking and charging its arguments. New arrays and
    dtypes are registered in `unbuilt`: the only objects BUILD may then fill."""

    def new(value):
        unbuilt[id(value)] = value
        return value

    def reconstruct(cls, shape, dtype):
        if cls is not _NDARRAY:
            raise _refuse(f"_reconstruct of {_shown(cls)}")
        dtype = _small_dtype(dtype)
        charge(_shape_bytes(shape, dtype), "array")
        return new(_multiarray._reconstruct(np.ndarray, shape, dtype))

    def scalar(dtype, data=None):
        if not isinstance(dtype, np.dtype):
            raise _refuse("numpy scalar without a dtype")
        charge(max(dtype.itemsize, len(data) if isinstance(data, (bytes, str)) else 0), "numpy scalar")
        return _multiarray.scalar(dtype, data) if data is not None else _multiarray.scalar(dtype)

    def frombuffer(buffer, dtype, shape, order):
        charge(len(memoryview(buffer).cast("B")), "array buffer")
        return _core.numeric._frombuffer(buffer, dtype, shape, order)

    def dtype(spec, align=False, copy=False):
        if not isinstance(spec, str):
            raise _refuse(f"numpy.dtype of a {type(spec).__name__}")
        # Always a copy: BUILD on the shared float64 descriptor would change it for the whole process.
        return new(np.dtype(_small_dtype(spec), align=bool(align), copy=True))

    def make_set(kind):
        def build(items=()):
            charge(_POINTER_BYTES * _sized(items, f"builtins.{kind.__name__}"), kind.__name__)
            return kind(items)
        return build

    def ordered_dict(items=()):
        charge(_POINTER_BYTES * _sized(items, "collections.OrderedDict"), "OrderedDict")
        return collections.OrderedDict(items)

    def default_dict(*args):
        if len(args) > 1:
            raise _refuse("collections.defaultdict with more than a factory")
        factory = args[0] if args else None
        if factory is None:
            return collections.defaultdict()
        if isinstance(factory, _Builtin) and factory.name in _FACTORY_NAMES:
            return collections.defaultdict(factory.type)
        raise _refuse(f"collections.defaultdict with factory {_shown(factory)}")

    def number_pair(real=0, imag=0):
        if not all(isinstance(v, (int, float)) for v in (real, imag)):
            raise _refuse("builtins.complex of a non-number")
        return complex(real, imag)

    def make_slice(*args):
        if len(args) > 3 or not all(v is None or isinstance(v, int) for v in args):
            raise _refuse("builtins.slice of non-integers")
        return slice(*args)

    def latin1(text, encoding="latin1"):
        if not isinstance(text, str) or encoding not in ("latin1", "latin-1"):
            raise _refuse(f"_codecs.encode with {_shown(encoding)}")
        charge(len(text), "bytes")
        return codecs.encode(text, "latin1")

    def make_bytearray(data=b"", encoding=None):
        if isinstance(data, str):
            data = latin1(data, encoding or "latin1")
        elif not isinstance(data, (bytes, bytearray)):
            raise _refuse("builtins.bytearray of a non-bytes value")
        charge(len(data), "bytearray")
        return bytearray(data)

    calls = {"set": make_set(set), "frozenset": make_set(frozenset), "complex": number_pair, "slice": make_slice,
             "bytearray": make_bytearray}
    types = {"set": set, "frozenset": frozenset, "complex": complex, "slice": slice, "bytearray": bytearray,
             "list": list, "dict": dict, "int": int, "float": float, "str": str, "tuple": tuple}
    out: dict[tuple[str, str], object] = {("numpy", "ndarray"): _NDARRAY, ("numpy", "dtype"): dtype,
                                          ("collections", "OrderedDict"): ordered_dict,
                                          ("collections", "defaultdict"): default_dict, ("_codecs", "encode"): latin1}
    for core in _NUMPY_CORES:
        out[(f"{core}.multiarray", "_reconstruct")] = reconstruct
        out[(f"{core}.multiarray", "scalar")] = scalar
        out[(f"{core}.numeric", "_frombuffer")] = frombuffer
    for module in ("builtins", "__builtin__"):
        for name, type_ in types.items():
            out[(module, name)] = _Builtin(name, type_, calls.get(name))
    out[("__builtin__", "long")], out[("__builtin__", "unicode")] = _Builtin("long", int), _Builtin("unicode", str)
    out.update({key: _DictClass(".".join(key)) for key in _DICT_CLASSES})
    out.update({(module, name): _EnumClass(module, name, charge) for module in ("__main__", *_WRITER_ENUM_MODULES)
                for name in WRITER_ENUMS})
    assert set(out) == set(ALLOWED_GLOBALS)
    return out


def _array_state_bytes(state) -> int:
    """Bytes `ndarray.__setstate__(state)` will allocate: (version,) shape, dtype, fortran, data."""
    if not isinstance(state, tuple) or len(state) not in (4, 5):
        raise pickle.UnpicklingError("bad ndarray state")
    shape, dtype = state[-4], state[-3]
    if not isinstance(dtype, np.dtype):
        raise pickle.UnpicklingError("bad ndarray state (no dtype)")
    return _shape_bytes(shape, dtype)


def _dtype_state(dtype: np.dtype, state) -> tuple:
    """The state numpy writes for `dtype` with the byte order `state` asks for. Only plain dtypes:
    fields, sub-arrays and datetime units carry offsets and sizes numpy would trust."""
    plain = (isinstance(state, tuple) and len(state) in (8, 9) and state[0] in (3, 4)
             and state[1] in ("<", ">", "|", "=") and state[2:5] == (None, None, None)
             and (len(state) == 8 or state[8] is None))
    if not plain:
        raise _refuse("numpy dtype state (only plain dtypes: no fields, sub-arrays or datetime units)")
    return dtype.newbyteorder(state[1]).__reduce__()[2]


# Opcodes a ScenarioNet pickle never needs: they build class instances or fetch external objects
# (NEWOBJ is handled apart: allowed for the `_DictClass` stand-ins only).
_FORBIDDEN_OPCODES = {pickle.NEWOBJ_EX: "NEWOBJ_EX", pickle.INST: "INST", pickle.OBJ: "OBJ",
                      pickle.EXT1: "EXT1", pickle.EXT2: "EXT2", pickle.EXT4: "EXT4", pickle.PERSID: "PERSID",
                      pickle.BINPERSID: "BINPERSID"}


def _counted(handler):
    def run(self):
        self._opcodes += 1
        if self._max_opcodes is not None and self._opcodes > self._max_opcodes:
            raise PickleLimitError(f"runs more than {self._max_opcodes} pickle opcodes")
        handler(self)
    return run


def _forbidden(name: str):
    def run(self):
        raise RefusedGlobalError(f"refused pickle opcode {name} (only plain containers and numpy arrays are allowed)")
    return run


class RestrictedUnpickler(pickle._Unpickler):
    """Unpickler with an allow-list of globals, checked calls and the build caps of `limits`."""

    dispatch = {op: _counted(handler) for op, handler in pickle._Unpickler.dispatch.items()}

    def __init__(self, file, limits: PickleLimits = SCENARIO_LIMITS, size: int | None = None):
        super().__init__(file, encoding="latin1")  # Python 2 pickles: numpy needs str as latin-1 bytes
        self._charge = _Charges(limits.max_built_bytes)
        self._unbuilt: dict[int, object] = {}  # id -> new array / dtype that BUILD may fill once
        self._globals = _checked_globals(self._charge, self._unbuilt)
        self._opcodes, self._max_opcodes = 0, limits.max_opcodes
        self._size = size  # bytes in the whole pickle, when known

    def find_class(self, module: str, name: str):
        try:
            return self._globals[(module, name)]
        except (KeyError, TypeError):
            raise _refuse(f"{module}.{name}") from None

    def load_build(self):
        """BUILD only fills what our stand-ins just made, once: a new empty array (its size charged
        before numpy allocates) or a dtype copy (given back the state numpy itself would write, so
        a forged state cannot leave numpy with an inconsistent descriptor)."""
        if len(self.stack) < 2:
            raise pickle.UnpicklingError("BUILD on an empty stack")
        state, inst = self.stack[-1], self.stack[-2]
        if self._unbuilt.pop(id(inst), None) is not inst:
            raise _refuse(f"state of a {type(inst).__name__} (BUILD) that is not a new array or dtype")
        if isinstance(inst, np.ndarray):
            self._charge(_array_state_bytes(state), "array")
            state = self.stack.pop()
            inst.__setstate__(state)
        else:
            self.stack.pop()
            inst.__setstate__(_dtype_state(inst, state))

    def load_newobj(self):
        """NEWOBJ builds only a plain dict, for a writer's dict subclass (`_DictClass`) and no arguments."""
        if len(self.stack) < 2:
            raise pickle.UnpicklingError("NEWOBJ on an empty stack")
        args, cls = self.stack[-1], self.stack[-2]
        if not isinstance(cls, _DictClass) or args != ():
            raise RefusedGlobalError("refused pickle opcode NEWOBJ (only plain containers and numpy arrays are "
                                     "allowed)")
        del self.stack[-2:]
        self.append({})

    def load_bytearray8(self):
        """The stock version allocates the announced length before reading: a corrupt length would
        be a many-gigabyte allocation from 9 bytes."""
        (length,) = struct.unpack("<Q", self.read(8))
        if self._size is not None and length > self._size:
            raise pickle.UnpicklingError(f"bytearray of {length} bytes in a {self._size}-byte pickle")
        self._charge(length, "bytearray")
        data = self.read(length)
        if len(data) != length:
            raise pickle.UnpicklingError("pickle data was truncated")
        self.append(bytearray(data))


RestrictedUnpickler.dispatch[pickle.BUILD[0]] = _counted(RestrictedUnpickler.load_build)
RestrictedUnpickler.dispatch[pickle.BYTEARRAY8[0]] = _counted(RestrictedUnpickler.load_bytearray8)
RestrictedUnpickler.dispatch[pickle.NEWOBJ[0]] = _counted(RestrictedUnpickler.load_newobj)
RestrictedUnpickler.dispatch.update({op[0]: _forbidden(name) for op, name in _FORBIDDEN_OPCODES.items()})


# --- expansion of the result -------------------------------------------------------------------------
_CONTAINERS = (dict, list, tuple, set, frozenset)


def _is_branch(value) -> bool:
    return isinstance(value, _CONTAINERS) or (isinstance(value, np.ndarray) and value.dtype.hasobject)


def _children(value) -> tuple | None:
    """The values a container holds (object arrays included), None for a leaf."""
    if isinstance(value, dict):
        return (*value.keys(), *value.values())
    if isinstance(value, _CONTAINERS):
        return tuple(value)
    if isinstance(value, np.ndarray) and value.dtype.hasobject:
        return tuple(value.flat)
    return None


def _own_bytes(value) -> int:
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, (str, bytes, bytearray)):
        return len(value)
    return 0


def expanded_size(root, limits: PickleLimits = SCENARIO_LIMITS) -> tuple[int, int]:
    """(values, payload bytes) of `root` with every shared reference counted again, in time linear
    in the number of distinct containers (each subtree is measured once and memoised). A reference
    cycle is legitimate (writers made them) and its back-reference counts as one value."""
    measured: dict[int, tuple[int, int]] = {}  # id of a container -> its expanded size
    open_ids: set[int] = set()  # containers on the current path: meeting one again is a cycle
    stack: list[tuple] = [(root, 0, None)]  # (value, depth, its children once opened)
    while stack:
        value, depth, children = stack.pop()
        if children is not None:  # all children measured: close it
            nodes, data = 1, _own_bytes(value)
            for child in children:
                size = measured.get(id(child))  # ids of live objects are unique: leaves are never in it
                if size is None:
                    nodes, data = nodes + 1, data + _own_bytes(child)
                else:
                    nodes, data = nodes + size[0], data + size[1]
            open_ids.discard(id(value))
            measured[id(value)] = (nodes, data)
            _check_expansion(nodes, data, limits)
            continue
        if id(value) in measured:
            continue
        children = _children(value)
        if children is None:  # only the root can be a leaf here
            return 1, _own_bytes(value)
        if id(value) in open_ids:
            # A reference back to a container being measured (MetaDrive's old converters wrote a speed
            # bump whose "type" is the bump itself): counted once, as its parent counts an unmeasured child.
            continue
        if limits.max_depth is not None and depth > limits.max_depth:
            raise PickleLimitError(f"is nested more than {limits.max_depth} levels deep")
        open_ids.add(id(value))
        stack.append((value, depth, children))
        stack.extend((child, depth + 1, None) for child in children if _is_branch(child) and id(child) not in measured)
    return measured[id(root)]


def _check_expansion(nodes: int, data: int, limits: PickleLimits) -> None:
    if limits.max_nodes is not None and nodes > limits.max_nodes:
        raise PickleLimitError(f"expands to more than {limits.max_nodes} values (shared references counted "
                               f"each time)")
    if limits.max_data_bytes is not None and data > limits.max_data_bytes:
        raise PickleLimitError(f"expands to more than {limits.max_data_bytes} bytes of array data (shared "
                               f"references counted each time)")


# --- entry points ------------------------------------------------------------------------------------
def loads_restricted(data: bytes, limits: PickleLimits = SCENARIO_LIMITS):
    """Unpickles bytes with the allow-list and caps; raises RefusedGlobalError, PickleLimitError or
    the pickle module's errors."""
    if limits.max_file_bytes is not None and len(data) > limits.max_file_bytes:
        raise PickleLimitError(f"is {len(data)} bytes, more than the {limits.max_file_bytes} allowed")
    value = RestrictedUnpickler(io.BytesIO(data), limits, size=len(data)).load()
    if limits.max_nodes is not None or limits.max_data_bytes is not None or limits.max_depth is not None:
        expanded_size(value, limits)
    return value


def load_pickle(path: str | os.PathLike, limits: PickleLimits = SCENARIO_LIMITS):
    """Reads one pickle file safely. Any problem -> `InputError` naming the file (one line)."""
    from scenariomax.errors import InputError

    try:
        size = os.path.getsize(path)
        if limits.max_file_bytes is not None and size > limits.max_file_bytes:
            raise InputError(f"{path}: {size} bytes, more than the {limits.max_file_bytes} a pickle may have")
        with open(path, "rb") as stream:
            data = stream.read()
    except OSError as error:
        raise InputError(f"{path}: cannot read ({error.strerror or error})") from None
    try:
        return loads_restricted(data, limits)
    except (RefusedGlobalError, PickleLimitError) as error:
        raise InputError(f"{path}: {' '.join(str(error).split())}") from None
    except RecursionError:
        raise InputError(f"{path}: not a readable pickle (nested too deeply)") from None
    except Exception as error:  # noqa: BLE001 - corrupted pickles raise many kinds of errors
        reason = " ".join(str(error).split()) or type(error).__name__
        raise InputError(f"{path}: not a readable pickle ({type(error).__name__}: {reason[:200]})") from None
