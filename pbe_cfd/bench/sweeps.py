"""numba sweeps of the throughput study: many right-hand-side evaluations over many cells, and
the kernel-only ceilings of QMOM (pair rates on precomputed property rows) and of the Laguerre
ROM (the bare quadratic form)."""
import numba as nb
import numpy as np

from ..methods.dispatch import WORK_SIZE, method_rhs
from ..methods.qmom import invert as _qmom_invert
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


@nb.njit(cache=True, parallel=True)
def qmom_node_properties(states, cells, params, config, props, counts, factors):
    """Per cell: the quadrature's property rows (nodes, then the droplet in row n_max), the
    node count and the kernel's cell factor, as qmom_rhs computes them (setup of the
    kernel-only sweep)."""
    from_q = config[P.ORDER]
    for c in nb.prange(states.shape[0]):
        nodes = np.zeros(from_q)
        weights = np.zeros(from_q)
        binder = np.zeros(from_q)
        work = np.empty(WORK_SIZE)
        n = _qmom_invert(states[c], config, nodes, weights, binder, work)
        counts[c] = n
        num = 0.0
        den = 0.0
        for a in range(n):
            b = min(max(binder[a], 0.0), nodes[a])
            particle_properties(nodes[a] * params[P.MASS_SCALE], b * params[P.MASS_SCALE],
                                params, config, props[c], a)
            num += weights[a] * nodes[a] * props[c][a, DIAMETER]
            den += weights[a] * nodes[a]
        pd = params[P.DROPLET_MASS]
        particle_properties(pd, pd, params, config, props[c], from_q)
        factors[c] = kernel_cell_factor(config[P.KERNEL], cells[c, P.ALPHA], cells[c, P.THETA],
                                        num / den if den > 0 else 0.0, params)


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
