"""A restricted unpickler for ScenarioNet `.pkl` files, which are untrusted, executable input.

Only the globals needed to rebuild plain containers and numpy arrays are allowed; any other global
(os.system, builtins.exec, a class from some package...) is refused before it is ever looked up,
so nothing from the file is executed.
"""

from __future__ import annotations

import collections
import io
import os
import pickle

import numpy as np

_core = np._core if hasattr(np, "_core") else np.core  # numpy 2 vs 1
_multiarray = _core.multiarray

# (module, name) -> object. Both numpy 1 (`numpy.core`) and numpy 2 (`numpy._core`) spellings.
ALLOWED_GLOBALS = {
    ("numpy.core.multiarray", "_reconstruct"): _multiarray._reconstruct,
    ("numpy._core.multiarray", "_reconstruct"): _multiarray._reconstruct,
    ("numpy.core.multiarray", "scalar"): _multiarray.scalar,
    ("numpy._core.multiarray", "scalar"): _multiarray.scalar,
    ("numpy.core.numeric", "_frombuffer"): _core.numeric._frombuffer,  # arrays in pickle protocol 5
    ("numpy._core.numeric", "_frombuffer"): _core.numeric._frombuffer,
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("collections", "OrderedDict"): collections.OrderedDict,
    ("builtins", "set"): set,
    ("builtins", "frozenset"): frozenset,
    ("__builtin__", "set"): set,  # protocol <= 2 spells builtins the Python 2 way
    ("__builtin__", "frozenset"): frozenset,
    ("_codecs", "encode"): __import__("codecs").encode,  # bytes in pickle protocol 2 (str -> bytes only)
}


class RefusedGlobalError(pickle.UnpicklingError):
    """The pickle asked for a global outside the allow-list."""


class RestrictedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        try:
            return ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            raise RefusedGlobalError(f"refused pickle global {module}.{name} (only plain containers and "
                                     f"numpy arrays are allowed)") from None


def loads_restricted(data: bytes):
    """Unpickles bytes with the allow-list; raises RefusedGlobalError or the pickle module's errors."""
    return RestrictedUnpickler(io.BytesIO(data)).load()


def load_pickle(path: str | os.PathLike):
    """Reads one pickle file safely. Any problem -> `InputError` naming the file (one line)."""
    from scenariomax.sources.base import InputError

    try:
        with open(path, "rb") as stream:
            data = stream.read()
    except OSError as error:
        raise InputError(f"{path}: cannot read ({error.strerror or error})") from None
    try:
        return loads_restricted(data)
    except RefusedGlobalError as error:
        raise InputError(f"{path}: {error}") from None
    except Exception as error:  # noqa: BLE001 - corrupted pickles raise many kinds of errors
        reason = " ".join(str(error).split()) or type(error).__name__
        raise InputError(f"{path}: not a readable pickle ({type(error).__name__}: {reason})") from None
