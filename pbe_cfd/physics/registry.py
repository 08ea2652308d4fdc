"""The machinery of the physics registries: numba dispatch generated from registry entries.

numba caches compiled code only for a static call graph, so a registry code cannot select a
function at run time through a table of function objects. Instead each dispatcher here is
built from the registry entries as a chain of small inlined functions, one explicit branch per
entry (``if code == entry.code: return entry.function(...)``), ending in a branch for unknown
codes (NaN, 0 or False). numba inlines the whole chain into its callers, so the compiled code
is the if-chain one would write by hand, with no branch to forget: adding an entry to a
registry adds its branch to every dispatcher built from it.

Each builder takes ``cases``: (code, function or value) pairs in registry order. A new
registry (for example breakage selection functions) builds its dispatchers with the builders
here whose call signature matches, or adds one more builder of the same shape.
"""
import math

import numba as nb


# ---------------------------------------------------------------------------- lookups
def code_lookup(cases, default):
    """numba ``f(code)`` returning the value of the case with that code, ``default`` for an
    unknown code (values: int, float or bool constants)."""
    @nb.njit(cache=True, inline="always")
    def unknown(code):
        return default

    chain = unknown
    for case_code, value in reversed(tuple(cases)):
        chain = _lookup_link(case_code, value, chain)
    return chain


def _lookup_link(case_code, value, rest):
    @nb.njit(cache=True, inline="always")
    def link(code):
        if code == case_code:
            return value
        return rest(code)
    return link


# ---------------------------------------------------------------------------- pair functions
def pair_dispatch(cases):
    """numba ``f(code, props, a, c, factor, params)`` calling the case's
    ``function(props, a, c, factor, params)``; NaN for an unknown code."""
    @nb.njit(cache=True, inline="always")
    def unknown(code, props, a, c, factor, params):
        return math.nan

    chain = unknown
    for case_code, function in reversed(tuple(cases)):
        chain = _pair_link(case_code, function, chain)
    return chain


def _pair_link(case_code, function, rest):
    @nb.njit(cache=True, inline="always")
    def link(code, props, a, c, factor, params):
        if code == case_code:
            return function(props, a, c, factor, params)
        return rest(code, props, a, c, factor, params)
    return link


# ---------------------------------------------------------------------------- cell functions
def cell_dispatch(cases):
    """numba ``f(code, alpha, theta, d43, params)`` calling the case's
    ``function(alpha, theta, d43, params)``; NaN for an unknown code."""
    @nb.njit(cache=True, inline="always")
    def unknown(code, alpha, theta, d43, params):
        return math.nan

    chain = unknown
    for case_code, function in reversed(tuple(cases)):
        chain = _cell_link(case_code, function, chain)
    return chain


def _cell_link(case_code, function, rest):
    @nb.njit(cache=True, inline="always")
    def link(code, alpha, theta, d43, params):
        if code == case_code:
            return function(alpha, theta, d43, params)
        return rest(code, alpha, theta, d43, params)
    return link


# ---------------------------------------------------------------------------- switched factors
def switched_product(cases):
    """numba ``f(props, a, c, u0, params, config)``: the product of the case functions
    ``function(props, a, c, u0, params)`` whose switch ``config[slot] == 1``, in registry order
    (cases: (slot, function)); 1 if none is on. Once the product is 0 the remaining factors are
    not evaluated."""
    @nb.njit(cache=True, inline="always")
    def done(props, a, c, u0, params, config, psi):
        return psi

    chain = done
    for slot, function in reversed(tuple(cases)):
        chain = _product_link(slot, function, chain)

    @nb.njit(cache=True, inline="always")
    def product(props, a, c, u0, params, config):
        return chain(props, a, c, u0, params, config, 1.0)
    return product


def _product_link(slot, function, rest):
    @nb.njit(cache=True, inline="always")
    def link(props, a, c, u0, params, config, psi):
        if config[slot] == 1 and psi > 0.0:
            psi *= function(props, a, c, u0, params)
        return rest(props, a, c, u0, params, config, psi)
    return link


def switched_union(cases):
    """numba ``f(config)``: the bitwise or of the case values (int flags) whose switch
    ``config[slot] == 1`` (cases: (slot, value)); 0 if none is on."""
    @nb.njit(cache=True, inline="always")
    def done(config, acc):
        return acc

    chain = done
    for slot, value in reversed(tuple(cases)):
        chain = _union_link(slot, value, chain)

    @nb.njit(cache=True, inline="always")
    def union(config):
        return chain(config, 0)
    return union


def _union_link(slot, value, rest):
    @nb.njit(cache=True, inline="always")
    def link(config, acc):
        if config[slot] == 1:
            acc |= value
        return rest(config, acc)
    return link
