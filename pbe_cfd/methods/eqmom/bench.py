"""EQMOM's hook for the throughput study's kernel-only ceiling (``bench.throughput``): the
property rows of every cell's secondary particles, then the droplet, for the bench's
``points_kernel_sweep`` (what the pair physics over the particles costs alone)."""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.kernels import kernel_cell_factor
from ...physics.properties import DIAMETER
from ...physics.rates import particle_properties
from . import state as S


def ceiling_rows(config, aux):
    """Rows per cell the property array needs: the most secondary particles, plus the
    droplet."""
    return int(config[P.ORDER]) * int(aux[S.AUX_SECONDARY]) + 1


@nb.njit(cache=True, parallel=True)
def point_properties(states, cells, aux, params, config, props, counts, factors):
    """Per cell (states, cells: one row each): the secondary particles' property rows
    (SI masses), their count and the kernel's cell factor from their d43 [m]."""
    n_max = config[P.ORDER]
    drop = props.shape[1] - 1
    o = S.off_particles(n_max)
    mm = S.max_particles(n_max)
    for c in nb.prange(states.shape[0]):
        work = np.empty(S.work_size(n_max, config[P.N_STATE]))
        S.invert(states[c], aux, config, work)
        m = int(work[S.PARTICLES])
        num = 0.0
        den = 0.0
        for k in range(m):
            x = work[o + k]
            particle_properties(x * params[P.MASS_SCALE],
                                min(max(work[o + 2 * mm + k], 0.0), x) * params[P.MASS_SCALE],
                                params, config, props[c], k)
            num += work[o + mm + k] * x * props[c][k, DIAMETER]
            den += work[o + mm + k] * x
        counts[c] = m
        pd = params[P.DROPLET_MASS]
        particle_properties(pd, pd, params, config, props[c], drop)
        factors[c] = kernel_cell_factor(config[P.KERNEL], cells[c, P.ALPHA], cells[c, P.THETA],
                                        num / den if den > 0 else 0.0, params)
