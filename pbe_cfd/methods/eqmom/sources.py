"""EQMOM moment sources (gamma or lognormal kernels) and the integrator's hooks (rhs,
realizable, project, conserved) with the signatures of ``methods.dispatch``.

The sources are QMOM's integrals evaluated on the secondary particles (X_j, W_j, B_j) of the
kernels (``state``): aggregation over each unordered pair of particles (and a particle with
itself), breakage per particle, droplet capture per particle and injection as in QMOM. With
N + 2 secondary nodes per kernel they are exact over the reconstruction for the constant and
sum kernels and for the power-law selection with a <= 2 (see ``state.secondary_nodes``); the
lognormal kernels' 20 Gauss-Hermite particles are exact for no power, within ~1e-7 of the
reconstruction for the orders these sources use (docs/physics.md section 16).
Units: scaled moments per s (``state``); rates from ``physics`` in SI.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.breakage import cell_selection_factor, daughter_moment_factor
from ...physics.drying import cell_gas
from ...physics.injection import droplet_liquid_entry, evaporated_entry
from ...physics.kernels import kernel_cell_factor, kernel_uses_d43
from ...physics.properties import DIAMETER, N_PROPS
from ...physics.rates import pair_rate, particle_properties
from ..quadrature.aggregation_sources import add_pair_sources
from ..quadrature.binder import binder_within_mass
from ..quadrature.breakage_sources import node_selection_rate
from ..quadrature.drying_sources import (add_droplet_class_terms, drift_moment_rate,
                                         droplet_point, point_drying_rate,
                                         set_droplet_invariants, tail_entries)
import pbe_cfd.methods.quadrature.gamma_inversion as I
import pbe_cfd.methods.eqmom.state as S

_as_strided = np.lib.stride_tricks.as_strided


@nb.njit(cache=True, inline="always")
def _props_view(work, n_max):
    o = S.off_props(n_max)
    rows = S.max_particles(n_max) + 1
    return _as_strided(work[o:o + rows * N_PROPS], shape=(rows, N_PROPS),
                       strides=(N_PROPS * 8, 8))


@nb.njit(cache=True, error_model="numpy", inline="always")
def _breakage(out, X, W, B, m, cell, n_size, n_max, bivariate, params, config):
    """Breakage sources per particle: w S(x) (F(i + j) - 1) x^i b^j (breakage_sources)."""
    factor = cell_selection_factor(cell, params, config)
    if factor == 0.0:
        return
    code = config[P.BREAKAGE_DAUGHTERS]
    for a in range(m):
        rate = node_selection_rate(X[a], factor, params, config)
        if rate == 0.0:
            continue
        power = W[a] * rate
        for k in range(n_size):
            if k != 1:
                out[k] += power * (daughter_moment_factor(code, float(k)) - 1.0)
            if bivariate and k < n_max and k != 0:
                out[n_size + k] += power * B[a] * (daughter_moment_factor(code, float(k + 1))
                                                   - 1.0)
            power *= X[a]


@nb.njit(cache=True, error_model="numpy", inline="always")
def _droplets(state, out, X, W, B, m, props, factor, u0, cell, n_size, n_max, bivariate,
              params, config):
    """Droplet capture by the particles (separate droplets) and injection (module qmom)."""
    n_state = config[P.N_STATE]
    number_scale = params[P.NUMBER_SCALE]
    inj = cell[P.INJECTION] / number_scale
    pd, bd = droplet_point(state, params, config)   # one droplet now (p_d, b_d = p_d: fresh)
    xd = pd / params[P.MASS_SCALE]
    xl = bd / params[P.MASS_SCALE]
    row = S.max_particles(n_max)
    if config[P.SEPARATE_DROPLETS] == 1:
        nd = state[n_state - 1]
        captured = 0.0
        if (nd > 0.0 and factor != 0.0 and m > 0
                and (pd > 0.0 or droplet_liquid_entry(config) < 0)):
            particle_properties(pd, bd, params, config, props, row)
            droplet_factor = number_scale * params[P.DROPLET_FACTOR]
            for a in range(m):
                flux = nd * W[a] * droplet_factor * pair_rate(props, a, row, factor, u0,
                                                              params, config)
                captured += flux
                xa = X[a]
                s = xa + xd
                h = 0.0
                pa = 1.0
                for k in range(1, n_size):
                    h = s * h + xd * pa
                    pa *= xa
                    out[k] += flux * h
                if bivariate:
                    ba = B[a]
                    h = 0.0
                    pa = 1.0
                    total = 1.0
                    for k in range(n_max):
                        out[n_size + k] += flux * (ba * h + xl * total)
                        h = s * h + xd * pa
                        pa *= xa
                        total *= s
            out[n_state - 1] -= captured
        out[n_state - 1] += inj
        add_droplet_class_terms(state, out, inj, captured, xl,
                                cell_gas(cell, params, config), params, config)
    elif inj != 0.0:
        value = inj
        for k in range(n_size):
            out[k] += value
            if bivariate and k < n_max:
                out[n_size + k] += value * xl
            value *= xd


@nb.njit(cache=True, error_model="numpy", inline="always")
def _drying(out, X, W, B, m, n_size, n_max, bivariate, gas, params, config):
    """Drying drift of the m secondary particles in the cell's ``gas``
    (``physics.drying.cell_gas``; docs/physics.md section 15; as QMOM's nodes): M_kl gains -W e (k X^(k-1) B^l + l X^k B^(l-1)), the evaporated liquid (entry
    N_STATE - 1 - SEPARATE_DROPLETS) W e."""
    evaporated = evaporated_entry(config)
    for a in range(m):
        x = X[a]
        b = min(max(B[a], 0.0), x)
        rate = W[a] * point_drying_rate(x, b, gas, params)
        if rate == 0.0:
            continue
        out[evaporated] += rate
        for k in range(1, n_size):
            out[k] += drift_moment_rate(k, 0, x, b, rate)
        if bivariate:
            for k in range(n_max):
                out[n_size + k] += drift_moment_rate(k, 1, x, b, rate)


@nb.njit(cache=True, error_model="numpy")
def eqmom_rhs(state, out, cell, aux, params, config, work):
    """d(state)/dt of one cell [scaled moments per s] (layout: ``state``). cell: (alpha [-],
    theta [m2/s2], collision velocity [m/s], injection [droplets/(m3 s)]); aux: [secondary
    nodes per kernel]; work: at least ``state.work_size``. No allocation."""
    n_max = config[P.ORDER]
    n_state = config[P.N_STATE]
    bivariate = config[P.BIVARIATE] == 1
    n_size = 2 * n_max + 1
    for k in range(n_state):
        out[k] = 0.0
    S.invert_work(state, aux, config, work)
    m = int(work[S.PARTICLES])
    o = S.off_particles(n_max)
    mm = S.max_particles(n_max)
    X = work[o:o + mm]
    W = work[o + mm:o + 2 * mm]
    B = work[o + 2 * mm:o + 3 * mm]
    props = _props_view(work, n_max)
    mass_scale = params[P.MASS_SCALE]
    code = config[P.KERNEL]
    with_d43 = kernel_uses_d43(code)
    num43 = 0.0
    den43 = 0.0
    for a in range(m):
        particle_properties(X[a] * mass_scale, min(max(B[a], 0.0), X[a]) * mass_scale, params,
                            config, props, a)
        if with_d43:
            num43 += W[a] * X[a] * props[a, DIAMETER]
            den43 += W[a] * X[a]
    d43 = num43 / den43 if den43 > 0.0 else 0.0
    factor = kernel_cell_factor(code, cell[P.ALPHA], cell[P.THETA], d43, params)
    u0 = cell[P.COLLISION_VELOCITY]
    number_scale = params[P.NUMBER_SCALE]
    if factor != 0.0:
        add_pair_sources(out, X, W, B, m, props, factor, u0, number_scale, n_size, n_max,
                         bivariate, params, config)
    if config[P.BREAKAGE] == 1:
        _breakage(out, X, W, B, m, cell, n_size, n_max, bivariate, params, config)
    if config[P.DRYING] == 1:
        _drying(out, X, W, B, m, n_size, n_max, bivariate, cell_gas(cell, params, config),
                params, config)
    _droplets(state, out, X, W, B, m, props, factor, u0, cell, n_size, n_max, bivariate,
              params, config)


@nb.njit(cache=True)
def eqmom_conserved(config, params, pivots, coefs):
    """Linear invariants (rows of coefs; pivots the entries of coefficient 1): granule mass
    M10 plus the free droplets' x_d n_d, and (bivariate) binder mass M01 plus x_d n_d, each
    plus the evaporated liquid with drying."""
    n_max = config[P.ORDER]
    n_state = config[P.N_STATE]
    separate = config[P.SEPARATE_DROPLETS] == 1
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    count = 2 if config[P.BIVARIATE] == 1 else 1
    for r in range(count):
        for k in range(n_state):
            coefs[r, k] = 0.0
        pivots[r] = 1 if r == 0 else 2 * n_max + 1
        coefs[r, pivots[r]] = 1.0
        if separate and not set_droplet_invariants(coefs, r, params, config):
            coefs[r, n_state - 1] = xd
        if config[P.DRYING] == 1:        # what evaporates leaves M10 and M01 for this entry
            coefs[r, n_state - 1 - config[P.SEPARATE_DROPLETS]] = 1.0
    return count


@nb.njit(cache=True, error_model="numpy")
def _project_into(state, target, config, work, family):
    """Moments of the reconstruction (kernels of the ``family``, fractions in ``work``) into
    target."""
    n_max = config[P.ORDER]
    n = int(work[S.KERNELS])
    sigma = work[S.SIGMA]
    n_size = 2 * n_max + 1
    for k in range(n_size + (n_max if config[P.BIVARIATE] == 1 else 0)):
        target[k] = 0.0
    for a in range(n):
        x = work[S.off_nodes(n_max) + a]
        w = work[S.off_weights(n_max) + a]
        y = work[S.off_fraction(n_max) + a]
        for k in range(n_size):
            mu = I.family_moment(x, sigma, k, family)
            target[k] += w * mu
            if config[P.BIVARIATE] == 1 and k < n_max:
                target[n_size + k] += w * y * I.family_moment(x, sigma, k + 1, family)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _check_state(state, aux, config, work, on_closure):
    """The tests of ``eqmom_realizable`` (on_closure False) or ``eqmom_on_closure`` (True)."""
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    n_size = 2 * n_max + 1
    for k in range(n_state):
        if not math.isfinite(state[k]):
            return False
    if config[P.SEPARATE_DROPLETS] == 1 and state[n_state - 1] < 0.0:
        return False
    if config[P.DRYING] == 1 and state[n_state - 1 - config[P.SEPARATE_DROPLETS]] < 0.0:
        return False
    if droplet_liquid_entry(config) >= 0 and state[droplet_liquid_entry(config)] < 0.0:
        return False
    if state[0] == 0.0:
        for k in range(n_state - tail_entries(config)):
            if state[k] != 0.0:
                return False
        return True
    if state[0] < 0.0:
        return False
    n = S.invert_work(state, aux, config, work)
    if n == 0:
        return False
    target = work[S.off_scratch(n_max):S.off_scratch(n_max) + n_size + n_max]
    status = int(work[S.STATUS])
    if status == I.REDUCED:
        _project_into(state, target, config, work, S.kernel_family(aux))
        for k in range(n_size):
            if abs(target[k] - state[k]) > S.PROJECTION_TOLERANCE * abs(state[k]):
                return False
    if config[P.BIVARIATE] == 1:
        if not binder_within_mass(state, n_size, n_max, S.PROJECTION_TOLERANCE):
            return False
        if not on_closure:
            return True
        # binder moments reproduced by the bounded per-kernel fractions
        _project_into(state, target, config, work, S.kernel_family(aux))
        for k in range(n_max):
            i = n_size + k
            if abs(target[i] - state[i]) > S.BINDER_TOLERANCE * abs(state[k + 1]):
                return False
    return True


@nb.njit(cache=True, error_model="numpy")
def eqmom_realizable(state, aux, params, config, work):
    """True if the state is a moment set the gamma-EQMOM represents, what a step must keep to
    be accepted: finite, non-negative number and droplets, invertible (M_2N not below the
    Gauss rule's), the moments a reduced fit drops consistent with it (PROJECTION_TOLERANCE)
    and 0 <= M_k1 <= M_(k+1)0 (b <= p in every particle). Binder moments the bounded
    per-kernel fractions do not reproduce are the closure's limit, not a reason to reject a
    step (as QMOM's): ``eqmom_project`` puts them on the bounded fractions after every accepted
    step, and ``eqmom_on_closure`` is the test for them. All zeros: realizable."""
    return _check_state(state, aux, config, work, False)


@nb.njit(cache=True, error_model="numpy")
def eqmom_on_closure(state, aux, params, config, work):
    """True if the state is realizable and on the EQMOM's closure, what a state mixed by
    transport must be to go without ``eqmom_project``: the tests of ``eqmom_realizable`` and
    besides the binder moments reproduced by the bounded fractions (BINDER_TOLERANCE of
    M_(k+1)0)."""
    return _check_state(state, aux, config, work, True)


@nb.njit(cache=True, error_model="numpy")
def eqmom_project(state, aux, params, config, work):
    """Re-project an accepted state onto its reconstruction, in place: a reduced fit's
    moments, the closest-sigma fit's M_2N, a fewer-kernel fit's M_(2n+1) .. M_2N, and the binder moments M_k1 (k >= 1) of the
    bounded fractions. M00, M10 and M01 (conserved) are never touched."""
    n_max = config[P.ORDER]
    n_size = 2 * n_max + 1
    if state[0] <= 0.0:
        return
    n = S.invert_work(state, aux, config, work)
    if n == 0:
        return
    target = work[S.off_scratch(n_max):S.off_scratch(n_max) + n_size + n_max]
    status = int(work[S.STATUS])
    bivariate = config[P.BIVARIATE] == 1
    if status != I.REDUCED and status != I.CLOSEST and status != I.FEWER and not bivariate:
        return
    _project_into(state, target, config, work, S.kernel_family(aux))
    if status == I.REDUCED:
        for k in range(2, n_size):
            state[k] = target[k]
    elif status == I.CLOSEST:
        state[n_size - 1] = target[n_size - 1]
    elif status == I.FEWER:            # n kernels fit M_0 .. M_2n: the moments beyond
        for k in range(2 * n + 1, n_size):
            state[k] = target[k]
    if bivariate:
        for k in range(1, n_max):
            state[n_size + k] = target[n_size + k]
