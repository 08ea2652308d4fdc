"""The wet-wet aggregation's moments of order 0 and 2 on the wet class's point measure
(``[method] number_closure = "points"``; docs/physics.md section 9.2, "The number row on the
wet point measure").

Aggregation alone lowers the granule number: for any positive population
d(M00)/dt = -1/2 of the double integral of beta psi n n <= 0. The tensors apply the kernel to
the signed m-term reconstruction; for a broad wet class (carried shape below 1) their number
row can be off several-fold and turn positive (``number_watch``; docs/results/laguerre.md, the
batch proxy). With this closure the wet-wet rows of W00, W20, W11 and W02 are instead pair sums
of the physics' own pair rate (``physics.rates.pair_rate``: the scene's kernel and
efficiencies at the cell's u0) over the positive point measure of the wet class with its
carried moments, ``drying.wet_points`` (two gamma-Gauss mass nodes from W00, W10, W20, each
with its conditional liquid points from W01, W11, W02, W12):

    dW~ij/dt = 1/2 N_ref sum_s sum_t w_s w_t beta_st [(x_s + x_t)^i (b_s + b_t)^j
                                                      - x_s^i b_s^j - x_t^i b_t^j],

i.e. -1/2 for W00, 2 x_s x_t for W20, x_s b_t + x_t b_s for W11, 2 b_s b_t for W02 [scaled
moments per s]. The four rows move together as the moments of one positive measure under
aggregation, so this term alone keeps W00 W20 >= W10^2, W00 W02 >= W01^2 and the second
moments' matrix as aggregation does for a population (W00 alone on the points, with W20
from the tensors, would not). W00 is clipped at 0 from above and the gains at 0
from below (a node's continued liquid pair may carry a small negative weight,
``drying._node_points``). W10 and W01 (exactly 0) and the rows of order 3 and 4 keep the
tensors' sources, as do the dry class and the dry-wet terms.
"""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.kernels import collision_velocity, kernel_cell_factor
from ...physics.properties import N_PROPS
from ...physics.rates import pair_rate, particle_properties
from .drying import N_POINTS, _point, wet_points
from .layout import AUX_ORDER


@nb.njit(cache=True)
def wet_pair_rates(state, cell, aux, params, config, d43):
    """(dW~00/dt, dW~20/dt, dW~11/dt, dW~02/dt) of wet-wet aggregation [scaled moments per
    s] on the wet point measure (module docstring). state: scaled moments; cell: the cell's
    row (ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY [m/s]: 4 sqrt(Theta / pi) where not
    positive); d43 [m]: the cell's volume-mean diameter (the ktgf kernel's cell factor)."""
    m = int(aux[AUX_ORDER])
    own = params[:P.N_PARAMS]           # the scene's slots: no held Stokes decision
    factor = kernel_cell_factor(config[P.KERNEL], cell[P.ALPHA], cell[P.THETA], d43, own)
    if factor == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    u0 = cell[P.COLLISION_VELOCITY]
    if not u0 > 0.0:
        u0 = collision_velocity(cell[P.THETA])
    pref = own[P.MASS_SCALE]
    pts = wet_points(state, m)
    props = np.zeros((N_POINTS, N_PROPS))
    x0, b0, w0 = _point(0, pts)
    x1, b1, w1 = _point(1, pts)
    x2, b2, w2 = _point(2, pts)
    x3, b3, w3 = _point(3, pts)
    x4, b4, w4 = _point(4, pts)
    x5, b5, w5 = _point(5, pts)
    mass = (x0, x1, x2, x3, x4, x5)           # N_POINTS = 6; tuples: only props allocated
    liquid = (b0, b1, b2, b3, b4, b5)
    weights = (w0, w1, w2, w3, w4, w5)
    for q in range(N_POINTS):
        if weights[q] != 0.0:
            particle_properties(mass[q] * pref, liquid[q] * pref, own, config, props, q)
    number = 0.0                        # each sum: 1/2 of the ordered double sum
    pp = 0.0
    pb = 0.0
    bb = 0.0
    for s in range(N_POINTS):
        ws = weights[s]
        if ws == 0.0:
            continue
        for t in range(s, N_POINTS):
            wt = weights[t]
            if wt == 0.0:
                continue
            f = (0.5 if t == s else 1.0) * ws * wt * pair_rate(props, s, t, factor, u0, own,
                                                                 config)
            number += f
            pp += f * mass[s] * mass[t]
            pb += f * (mass[s] * liquid[t] + mass[t] * liquid[s])
            bb += f * liquid[s] * liquid[t]
    nref = own[P.NUMBER_SCALE]
    return (min(-nref * number, 0.0), max(2.0 * nref * pp, 0.0), max(nref * pb, 0.0),
            max(2.0 * nref * bb, 0.0))
