"""The integration kernel's argument types: the method's functions as numba first-class
functions, and the kernel's signature.

The kernel takes the method's right-hand side, realizability test, projection and invariants
(``methods.registry``) as arguments of ``types.FunctionType`` and calls them through their
addresses, bundled in a ``MethodFunctions`` inside the kernel (``method.rhs(...)``). So the
kernel compiles once per scheme and argument types, whatever the method, and never links a
method's code into its own: numba optimises and generates the machine code of every callee it
links once more in each caller, which made the method's code compile at every level of the
integrator (docs/results/first-run.md). The method's functions compile on their own, for
``signatures``, and are handed to the kernel as their entry points (``addresses_of``).

The argument types are those of the kernel's call sites (``cell.integrate_cell``): the
per-cell vectors (a row of the states, of the cells' fields or of the step buffers, the
held parameters, the work array) are C-contiguous float64 vectors.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import typeof
from numba.core import types

from ..methods import registry
from ..physics import parameters as P
from .codes import N_BUF, N_STATS, UNREALIZABLE_START

#: the method's four functions, by name (dispatchers in Python, first-class functions in the
#: kernel): rhs(state, out, cell, aux, params, config, work); realizable(state, aux, params,
#: config, work) -> bool; project(state, aux, params, config, work) in place;
#: conserved(config, params, pivots, coefs) -> number of invariants
MethodFunctions = namedtuple("MethodFunctions", ["rhs", "realizable", "project", "conserved"])


def call_types(aux, params, config) -> dict:
    """The numba types of the kernel's call-site arguments for a packed scene: V a per-cell
    float vector of the state's length, M the step buffers, I the pivots, A aux, P params,
    C config, f a float, i an integer."""
    n = int(config[P.N_STATE])
    return dict(V=typeof(np.zeros(n)), M=typeof(np.zeros((N_BUF, n))),
                I=typeof(np.zeros(2, dtype=np.int64)), A=typeof(aux), P=typeof(params),
                C=typeof(config), f=types.float64, i=types.int64)


def argument_types(aux, params, config) -> MethodFunctions:
    """The argument types of each of the method's functions at the kernel's call sites."""
    t = call_types(aux, params, config)
    V, M, I, A, C = (t[k] for k in "VMIAC")
    return MethodFunctions(rhs=(V, V, V, A, V, C, V), realizable=(V, A, V, C, V),
                           project=(V, A, V, C, V), conserved=(C, V, I, M))


#: what each function returns
RETURNS = MethodFunctions(rhs=types.none, realizable=types.boolean, project=types.none,
                          conserved=types.int64)


def signatures(aux, params, config) -> MethodFunctions:
    """The numba signature (return and argument types) of each of the method's functions for
    a packed scene: what the kernel's first call compiles them for (with the return type,
    which is part of the key of numba's disk cache)."""
    args = argument_types(aux, params, config)
    return MethodFunctions(*(ret(*a) for ret, a in zip(RETURNS, args)))


class FunctionAddress:
    """A compiled function's entry point as numba unboxes a first-class function argument
    (its ``__wrapper_address__`` protocol): a call of the kernel then reads an integer, where
    a dispatcher argument is looked up and checked again at every call (about 25 us each,
    four per call of the kernel)."""

    __slots__ = ("address", "name")

    def __init__(self, address: int, name: str):
        self.address, self.name = address, name

    def __wrapper_address__(self) -> int:
        return self.address

    def __repr__(self) -> str:
        return f"FunctionAddress({self.name})"


_ADDRESSES = {}


def addresses_of(method: int, sigs: MethodFunctions) -> MethodFunctions:
    """The entry points (``FunctionAddress``) of the functions of the method with code
    ``method`` for the signatures ``sigs`` (``signatures``), each compiled, or loaded from
    numba's disk cache, on first use."""
    key = (int(method), tuple(sigs))
    found = _ADDRESSES.get(key)
    if found is None:
        found = MethodFunctions(*(_address(d, s) for d, s in zip(functions_of(method), sigs)))
        _ADDRESSES[key] = found
    return found


def _address(dispatcher, sig) -> FunctionAddress:
    """The entry point of ``dispatcher`` compiled for ``sig`` (a whole signature), as numba
    takes it for a first-class function of that signature: its C-callable wrapper. Compiled
    (or loaded) for the whole signature first, the key under which ``pbe-cfd compile``'s
    helpers cache it (numba before 0.68 looks a first-class function up by its argument
    types only, a key of its own in the disk cache)."""
    dispatcher.compile(sig)
    compiled = dispatcher.get_compile_result(sig)
    address = compiled.library.get_pointer_to_function(compiled.fndesc.llvm_cfunc_wrapper_name)
    return FunctionAddress(address, dispatcher.__qualname__)


def closure_check_address(method: int, sigs: MethodFunctions) -> FunctionAddress:
    """The entry point of the closure test (``MethodEntry.closure_test``) of the method with
    code ``method``, compiled (or loaded) for the realizability test's signature in ``sigs``:
    what the repair after transport calls (it keeps the address with its compiled kernel). A
    method known only to ``functions_of`` is tested by its realizability test."""
    entry = registry.entry_of_code(method)
    test = entry.closure_test if entry is not None else functions_of(method).realizable
    return _address(test, sigs.realizable)


def functions_of(method: int) -> MethodFunctions:
    """The dispatchers of the method with registry code ``method``."""
    entry = registry.entry_of_code(method)
    if entry is None:
        raise ValueError(f"config[METHOD] = {method}: no integrated method has this code")
    return MethodFunctions(entry.rhs, entry.realizable, entry.project, entry.conserved)


def kernel_signature(scheme, args, sigs=None):
    """The kernel's numba signature: the method's functions as first-class function types
    (of ``sigs``, default ``signatures`` of the scene in ``args``: the same for every
    method), the scheme code as a literal, the types of ``args`` (those of
    ``integrate_cells`` from states on), then a thread's first row and the stride
    (integers)."""
    states, cells, aux, params, config = args[:5]
    for name, arr in (("states", states), ("cells", cells)):
        if arr.ndim != 2 or not arr.flags.c_contiguous:
            raise ValueError(f"integrate_cells: {name} must be a C-contiguous 2-D array "
                             f"(rows of cells), got shape {arr.shape}")
    if sigs is None:
        sigs = signatures(aux, params, config)
    return (tuple(types.FunctionType(s) for s in sigs) + (types.literal(scheme),)
            + tuple(typeof(a) for a in args) + (types.int64, types.int64))


def probe_args(aux, params, config, n_cells):
    """Arguments of ``integrate_cells`` that run no cell (every status UNREALIZABLE_START)."""
    n = int(config[P.N_STATE])
    return (np.zeros((n_cells, n)), np.zeros((n_cells, P.N_CELL)), aux, params, config, 0.0,
            0.0, np.zeros(n_cells), 1e-8, 1e-14, 1, np.zeros((n_cells, N_STATS), dtype=np.int64),
            np.full(n_cells, UNREALIZABLE_START, dtype=np.int64), np.zeros(n_cells))


def layout_key(a):
    """What numba's type of an argument depends on, read without typing it (``typeof`` of
    every argument costs more than the kernel on a few cells): an array's dtype, dimensions,
    layout and flags, else the Python type."""
    if isinstance(a, np.ndarray):
        f = a.flags
        return (a.dtype.str, a.ndim, f.c_contiguous, f.f_contiguous, f.writeable, f.aligned)
    return type(a)
