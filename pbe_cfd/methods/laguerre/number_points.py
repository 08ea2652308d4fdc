"""The wet class's granule-number rate of aggregation on its point measure
(``[method] number_closure = "points"``; docs/physics.md section 9.2, "The number row").

Aggregation alone lowers the granule number: for any positive population
d(M00)/dt = -1/2 of the double integral of beta psi n n <= 0. The tensors apply the kernel to
the signed m-term reconstruction; for a broad wet class (carried shape below 1) its number row
can be off several-fold and turn positive (``number_watch``; docs/results/laguerre.md, the
batch proxy). With this closure the wet-wet aggregation's number row (W00) is instead the pair
sum of the physics' own pair rate (``physics.rates.pair_rate``: the scene's kernel and
efficiencies at the cell's u0) over the positive point measure of the wet class with its
carried moments, ``drying.wet_points`` (two gamma-Gauss mass nodes from W00, W10, W20, each
with its conditional liquid points from W01, W11, W02, W12):

    dW~00/dt = -1/2 N_ref sum_s sum_t w_s w_t beta_st  [scaled number per s],

clipped at 0 from above (a node's continued liquid pair may carry a small negative weight,
``drying._node_points``). Every other row keeps the tensors' Galerkin sources, so M10 and M01
stay exact. The dry class keeps its tensor rows: its D0 on points with D1, D2 from the tensors
broke D0 D2 >= D1^2 within 300 s on the batch proxy (measured), and dry-wet aggregates and
captures do not change W00.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.kernels import kernel_cell_factor
from ...physics.properties import N_PROPS
from ...physics.rates import pair_rate, particle_properties
from .drying import N_POINTS, _point, wet_points
from .layout import AUX_ORDER


@nb.njit(cache=True)
def wet_number_rate(state, cell, aux, params, config, d43):
    """dW~00/dt of wet-wet aggregation [scaled number per s] on the wet point measure (module
    docstring). state: scaled moments; cell: the cell's row (ALPHA [-], THETA [m2/s2],
    COLLISION_VELOCITY [m/s]: 4 sqrt(Theta / pi) where not positive); d43 [m]: the cell's
    volume-mean diameter (the ktgf kernel's cell factor)."""
    m = int(aux[AUX_ORDER])
    own = params[:P.N_PARAMS]           # the scene's slots: no held Stokes decision
    factor = kernel_cell_factor(config[P.KERNEL], cell[P.ALPHA], cell[P.THETA], d43, own)
    if factor == 0.0:
        return 0.0
    u0 = cell[P.COLLISION_VELOCITY]
    if not u0 > 0.0:
        theta = cell[P.THETA]
        u0 = 4.0 * math.sqrt(theta / math.pi) if theta > 0.0 else 0.0
    pref = own[P.MASS_SCALE]
    pts = wet_points(state, m)
    props = np.zeros((N_POINTS, N_PROPS))
    weights = np.zeros(N_POINTS)
    for q in range(N_POINTS):
        x, b, w = _point(q, pts)
        weights[q] = w
        if w != 0.0:
            particle_properties(x * pref, b * pref, own, config, props, q)
    total = 0.0                         # 1/2 of the ordered double sum
    for s in range(N_POINTS):
        ws = weights[s]
        if ws == 0.0:
            continue
        for t in range(s, N_POINTS):
            wt = weights[t]
            if wt == 0.0:
                continue
            beta = pair_rate(props, s, t, factor, u0, own, config)
            total += (0.5 if t == s else 1.0) * ws * wt * beta
    return min(-own[P.NUMBER_SCALE] * total, 0.0)
