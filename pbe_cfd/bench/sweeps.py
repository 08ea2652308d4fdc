"""numba sweeps of the throughput study: many right-hand-side evaluations over many cells, and
the kernel-only ceilings of QMOM (pair rates on precomputed property rows) and of the Laguerre
ROM (the bare quadratic form)."""
import numba as nb
import numpy as np

from ..methods.cqmom import cqmom as _cqmom
from ..methods.dispatch import WORK_SIZE, method_rhs
from ..methods.qmom.qmom import invert as _qmom_invert
from ..physics import parameters as P
from ..physics.kernels import kernel_cell_factor
from ..physics.properties import DIAMETER
from ..physics.rates import pair_rate, particle_properties


# ============================================================================ throughput kernels
@nb.njit(cache=True, parallel=True)
def rhs_sweep(states, cells, aux, params, config, reps, out):
    """``reps`` RHS evaluations per cell (prange over cells), each on a different row of
    ``states`` (row (c + 7919 r) mod n) so that nothing is reused between calls."""
    n = states.shape[0]
    for c in nb.prange(n):
        work = np.empty(WORK_SIZE)
        for r in range(reps):
            s = (c + 7919 * r) % n
            method_rhs(states[s], out[c], cells[c], aux, params, config, work)


@nb.njit(cache=True)
def node_property_rows(state, cell, params, config, nodes, weights, binder, work, props):
    """One cell's quadrature (into nodes, weights, binder), the property rows of its nodes and
    of the droplet (row n_max) and the kernel's cell factor, as qmom_rhs computes them.
    Returns (node count, cell factor)."""
    n_max = config[P.ORDER]
    n = _qmom_invert(state, config, nodes, weights, binder, work)
    num = 0.0
    den = 0.0
    for a in range(n):
        b = min(max(binder[a], 0.0), nodes[a])
        particle_properties(nodes[a] * params[P.MASS_SCALE], b * params[P.MASS_SCALE],
                            params, config, props, a)
        num += weights[a] * nodes[a] * props[a, DIAMETER]
        den += weights[a] * nodes[a]
    pd = params[P.DROPLET_MASS]
    particle_properties(pd, pd, params, config, props, n_max)
    return n, kernel_cell_factor(config[P.KERNEL], cell[P.ALPHA], cell[P.THETA],
                                 num / den if den > 0 else 0.0, params)


@nb.njit(cache=True, parallel=True)
def qmom_node_properties(states, cells, params, config, props, counts, factors):
    """Per cell: ``node_property_rows`` (setup of the kernel-only sweep)."""
    n_max = config[P.ORDER]
    for c in nb.prange(states.shape[0]):
        counts[c], factors[c] = node_property_rows(
            states[c], cells[c], params, config, np.zeros(n_max), np.zeros(n_max),
            np.zeros(n_max), np.empty(WORK_SIZE), props[c])


@nb.njit(cache=True, parallel=True)
def qmom_kernel_sweep(props, counts, cells, factors, params, config, reps, out):
    """Kernel-only ceiling of the QMOM RHS: per cell and repetition, the pair rates its RHS
    evaluates (N(N+1)/2 granule pairs and, with separate droplets, N droplet captures) through
    the registry's ``pair_rate`` on precomputed property rows -- nothing else."""
    n_max = config[P.ORDER]
    separate = config[P.SEPARATE_DROPLETS] == 1
    for c in nb.prange(props.shape[0]):
        pr = props[c]
        n = counts[c]
        u0 = cells[c, P.COLLISION_VELOCITY]
        acc = 0.0
        for r in range(reps):
            f = factors[c] * (1.0 + 1e-15 * r)
            for a in range(n):
                for b in range(a, n):
                    acc += pair_rate(pr, a, b, f, u0, params, config)
                if separate:
                    acc += pair_rate(pr, a, n_max, f, u0, params, config)
        out[c] = acc


@nb.njit(cache=True, parallel=True)
def cqmom_point_properties(states, cells, params, config, props, counts, factors):
    """Per cell: the property rows of the CQMOM points (packed, then the droplet in the last
    row), the point count and the kernel's cell factor (setup of the kernel-only sweep)."""
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    drop = props.shape[1] - 1
    op = 3 * n_max
    npt = n_max * m
    for c in nb.prange(states.shape[0]):
        work = np.empty(WORK_SIZE)
        n = _cqmom.invert(states[c], config, work)
        num = 0.0
        den = 0.0
        k = 0
        for a in range(n):
            for b in range(int(work[_cqmom.off_counts(n_max, m) + a])):
                i = a * m + b
                particle_properties(work[op + i] * params[P.MASS_SCALE],
                                    work[op + npt + i] * params[P.MASS_SCALE], params, config,
                                    props[c], k)
                num += work[op + 2 * npt + i] * work[op + i] * props[c][k, DIAMETER]
                den += work[op + 2 * npt + i] * work[op + i]
                k += 1
        counts[c] = k
        pd = params[P.DROPLET_MASS]
        particle_properties(pd, pd, params, config, props[c], drop)
        factors[c] = kernel_cell_factor(config[P.KERNEL], cells[c, P.ALPHA], cells[c, P.THETA],
                                        num / den if den > 0 else 0.0, params)


@nb.njit(cache=True, parallel=True)
def points_kernel_sweep(props, counts, cells, factors, params, config, reps, out):
    """Kernel-only ceiling of the CQMOM RHS: per cell and repetition, the registry's
    ``pair_rate`` of every pair of points and, with separate droplets, of every point with the
    droplet (last row) -- what a quadrature over the points costs in pair physics alone."""
    separate = config[P.SEPARATE_DROPLETS] == 1
    drop = props.shape[1] - 1
    for c in nb.prange(props.shape[0]):
        pr = props[c]
        n = counts[c]
        u0 = cells[c, P.COLLISION_VELOCITY]
        acc = 0.0
        for r in range(reps):
            f = factors[c] * (1.0 + 1e-15 * r)
            for a in range(n):
                for b in range(a, n):
                    acc += pair_rate(pr, a, b, f, u0, params, config)
                if separate:
                    acc += pair_rate(pr, a, drop, f, u0, params, config)
        out[c] = acc


@nb.njit(cache=True, parallel=True)
def laguerre_contraction_sweep(states, aux, reps, out):
    """Kernel-only ceiling of the Laguerre ROM: the bare quadratic form
    sum_{k<=l} Q[k, l, a] M_k M_l of one tensor slice (no interpolation, d43 or droplets)."""
    m = int(aux[1])
    K = m * m
    off = int(aux[7])
    n = states.shape[0]
    for c in nb.prange(n):
        for a in range(K):
            out[c, a] = 0.0
        for r in range(reps):
            st = states[(c + 7919 * r) % n]
            pos = off
            for k in range(K):
                mk = st[k]
                for l in range(k, K):
                    prod = mk * st[l]
                    for a in range(K):
                        out[c, a] += prod * aux[pos + a]
                    pos += K
