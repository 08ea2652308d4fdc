"""Aggregation sources of a quadrature: weighted particles -> moment sources.

A quadrature (QMOM's N nodes, or EQMOM's secondary particles of its kernels) represents the
granules as W_a particles of scaled mass X_a holding binder B_a. Each unordered pair (a, c),
a particle with itself counted half, aggregates at W_a W_c beta_ac; the moment gains follow
from recurrences in k with non-negative terms only (s = X_a + X_c):

    G_k = s^k - X_a^k - X_c^k:   G_1 = 0,  G_k = s G_(k-1) + X_c X_a^(k-1) + X_a X_c^(k-1)
    H_k = s^k - X_a^k:           H_0 = 0,  H_k = s H_(k-1) + X_c X_a^(k-1)

so the number (k = 0) loses exactly the pair and the mass moment (k = 1) gets exactly nothing;
the binder moments M_k1 gain B_a H_k(a, c) + B_c H_k(c, a). No cancellation, no allocation.

Units: masses in the method's scaled mass (SI / params[MASS_SCALE]), weights in its scaled
number density; sources in scaled moment units per second (the pair rate [m3/s] times
``number_scale`` [1/m3]).
"""
import numba as nb

from ...physics.rates import pair_rate


@nb.njit(cache=True, error_model="numpy", inline="always")
def add_pair_sources(out, X, W, B, m, props, factor, u0, number_scale, n_size, n_max,
                     bivariate, params, config):
    """Add the aggregation sources of the m particles (X, W, B) to ``out``: size moments
    out[0 .. n_size-1], binder moments out[n_size + k], k = 1 .. n_max-1 (bivariate only).
    props: the particles' properties rows (``physics.rates.particle_properties``); factor
    and u0 [m/s]: the cell's kernel factor and collision velocity (``physics.rates.pair_rate``)."""
    for a in range(m):
        xa = X[a]
        ba = B[a]
        for c in range(a, m):
            rate = number_scale * pair_rate(props, a, c, factor, u0, params, config)
            if rate == 0.0:
                continue
            pair = W[a] * W[c] * rate
            if a == c:
                pair *= 0.5
            out[0] -= pair
            xc = X[c]
            s = xa + xc
            g = 0.0
            pa = xa
            pc = xc
            for k in range(2, n_size):
                g = s * g + xc * pa + xa * pc
                pa *= xa
                pc *= xc
                out[k] += pair * g
            if bivariate:
                bc = B[c]
                ha = 0.0
                hc = 0.0
                pa = 1.0
                pc = 1.0
                for k in range(1, n_max):
                    ha = s * ha + xc * pa
                    hc = s * hc + xa * pc
                    pa *= xa
                    pc *= xc
                    out[n_size + k] += pair * (ba * ha + bc * hc)
