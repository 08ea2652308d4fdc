"""Sources of the CQMOM moment equations: aggregation, droplet capture, injection and breakage
by quadrature over the conditional points (layout and inversion in ``methods.cqmom``).

Granule-granule aggregation runs over pairs of size nodes: the collision frequency depends on
the masses only and is evaluated once per pair of size nodes, the success probability (which
depends on the binder fractions) once per pair of their points. The gains of every moment are
written as sums of non-negative terms, so the number loses exactly the aggregating pairs and
M10, M01 gain exactly nothing; droplet capture moves a granule (p, b) to (p + p_d, b + p_d).
Breakage: the size moments by quadrature over the size nodes, each mixed moment as its carried
value times the points' mean selection (``_breakage``). Drying (docs/physics.md section 15):
every point drifts at dx/dt = db/dt = -e(x, b) (``_drying``), its dry mass x - b fixed. All
quantities are scaled (see ``methods.cqmom``); no allocation.
"""
import numba as nb

from ...physics import parameters as P
from ...physics.drying import cell_gas
from ...physics.injection import droplet_liquid, droplet_liquid_entry, evaporated_entry
from ...physics.breakage import daughter_moment_factor
from ...physics.efficiency import efficiency_property_groups, pair_success_probability
from ...physics.kernels import (kernel_cell_factor, kernel_property_groups, kernel_uses_d43,
                                pair_collision_frequency)
from ...physics.properties import (BINDER_LAYER, DIAMETER, EKE_CBRT, EKE_INV, INV_DIAMETER_CUBED,
                                   WETTING, fill_properties)
from ...physics.rates import particle_properties
from ..quadrature.breakage_sources import cell_selection_factor, node_selection_rate
from ..quadrature.drying_sources import (add_droplet_class_terms, drift_moment_rate,
                                         droplet_point, point_drying_rate, tail_entries)
from .conditional import FREE, continued_fraction_points
from .cqmom import (invert_cached, mixed_index, off_acc, off_bpowers, off_cond, off_counts,
                    off_points, off_powers, off_scratch, props_view)


@nb.njit(cache=True, inline="always")
def _fill_properties(work, n_max, m, n, params, config):
    """Property rows of every point and the powers x_a^k (k < 2 N1), b_i^l (l < 2 N2);
    returns d43 [m] of the granules (where the kernel needs it, else 0). The size columns
    (cube roots) are computed once per size node and copied to its other points; only the
    binder columns (exponentials of y) are computed per point."""
    op = off_points(n_max)
    npt = n_max * m
    props = props_view(work, n_max, m)
    xpow = off_powers(n_max, m)
    bpow = off_bpowers(n_max, m)
    counts = off_counts(n_max, m)
    mass_scale = params[P.MASS_SCALE]
    groups = kernel_property_groups(config[P.KERNEL]) | efficiency_property_groups(config)
    binder_groups = groups & (WETTING | BINDER_LAYER)
    with_d43 = kernel_uses_d43(config[P.KERNEL])
    num43 = 0.0
    den43 = 0.0
    for a in range(n):
        xa = work[a]
        power = 1.0
        for k in range(2 * n_max):
            work[xpow + a * 2 * n_max + k] = power
            power *= xa
        first = a * m
        for b in range(int(work[counts + a])):
            i = first + b
            bi = work[op + npt + i]
            if b == 0:
                fill_properties(xa * mass_scale, bi * mass_scale, params, groups, props, i)
            else:
                fill_properties(xa * mass_scale, bi * mass_scale, params, binder_groups, props,
                                i)
                for col in (DIAMETER, INV_DIAMETER_CUBED, EKE_CBRT, EKE_INV):
                    props[i, col] = props[first, col]
            power = 1.0
            for l in range(2 * m):
                work[bpow + i * 2 * m + l] = power
                power *= bi
        if with_d43:
            wx = work[n_max + a] * xa
            num43 += wx * props[first, DIAMETER]
            den43 += wx
    return num43 / den43 if den43 > 0.0 else 0.0


@nb.njit(cache=True, error_model="numpy")
def _aggregation(out, work, n_max, m, n, factor, u0, params, config, bivariate):
    """Granule-granule aggregation over unordered pairs of points (scaled moments per s).

    Per pair of size nodes (a, c) the collision frequency (a function of the masses only) is
    evaluated once; per pair of their points the success probability. With s = x_a + x_c,
    t = b_i + b_j, the gain of M_kl is
      s^k t^l - x_a^k b_i^l - x_c^k b_j^l = x_a^k (t^l - b_i^l) + x_c^k (t^l - b_j^l) + G_k t^l,
    G_k = s^k - x_a^k - x_c^k >= 0 (k >= 1), and for k = 0: t^l - b_i^l - b_j^l; all terms are
    non-negative, the number loses exactly the pair and M10, M01 get exactly nothing.
    """
    op = off_points(n_max)
    npt = n_max * m
    counts = off_counts(n_max, m)
    props = props_view(work, n_max, m)
    bpow = off_bpowers(n_max, m)
    xpow = off_powers(n_max, m)
    acc = off_acc(n_max, m)
    lmax = 2 * m if bivariate else 1
    n_size = 2 * n_max
    number_scale = params[P.NUMBER_SCALE]
    code = config[P.KERNEL]
    for a in range(n):
        xa = work[a]
        for c in range(a, n):
            beta = pair_collision_frequency(code, props, a * m, c * m, factor, params)
            if beta == 0.0:
                continue
            beta *= number_scale
            xc = work[c]
            for q in range(4 * lmax):
                work[acc + q] = 0.0
            total = 0.0
            for b in range(int(work[counts + a])):
                i = a * m + b
                wi = work[op + 2 * npt + i]
                bi = work[op + npt + i]
                for d in range(b if a == c else 0, int(work[counts + c])):
                    j = c * m + d
                    rate = wi * work[op + 2 * npt + j] * beta * pair_success_probability(
                        props, i, j, u0, params, config)
                    if i == j:
                        rate *= 0.5
                    total += rate
                    if bivariate and rate != 0.0:
                        bj = work[op + npt + j]
                        t = bi + bj
                        tl = 1.0
                        ha = 0.0
                        hc = 0.0
                        g = 0.0
                        for l in range(1, lmax):
                            bil = work[bpow + i * 2 * m + l - 1]
                            bjl = work[bpow + j * 2 * m + l - 1]
                            ha = t * ha + bj * bil
                            hc = t * hc + bi * bjl
                            if l >= 2:
                                g = t * g + bj * bil + bi * bjl
                            tl *= t
                            work[acc + l] += rate * ha
                            work[acc + lmax + l] += rate * hc
                            work[acc + 2 * lmax + l] += rate * tl
                            work[acc + 3 * lmax + l] += rate * g
            if total == 0.0:
                continue
            out[0] -= total
            # size moments: G_k by G_k = s G_(k-1) + x_c x_a^(k-1) + x_a x_c^(k-1), G_1 = 0
            s = xa + xc
            g = 0.0
            for k in range(2, n_size):
                g = s * g + xc * work[xpow + a * n_size + k - 1] + xa * work[xpow + c * n_size
                                                                           + k - 1]
                out[k] += total * g
            if bivariate:
                _mixed_gains(out, work, n_max, lmax, a, c, xpow, acc)


@nb.njit(cache=True, inline="always")
def _mixed_gains(out, work, n_max, lmax, a, c, xpow, acc):
    """Add the mixed-moment gains of the size-node pair (a, c) from the accumulators of its
    point pairs (see ``_aggregation``)."""
    n_size = 2 * n_max
    xa = work[a]
    xc = work[c]
    s = xa + xc
    for l in range(2, lmax):
        out[mixed_index(n_max, 0, l)] += work[acc + 3 * lmax + l]
    g = 0.0
    for k in range(1, n_max):
        if k >= 2:
            g = s * g + xc * work[xpow + a * n_size + k - 1] + xa * work[xpow + c * n_size + k - 1]
        xak = work[xpow + a * n_size + k]
        xck = work[xpow + c * n_size + k]
        for l in range(1, lmax):
            out[mixed_index(n_max, k, l)] += (xak * work[acc + l] + xck * work[acc + lmax + l]
                                               + g * work[acc + 2 * lmax + l])


@nb.njit(cache=True, error_model="numpy")
def _droplet_capture(out, state, work, n_max, m, n, factor, u0, params, config, bivariate):
    """Capture of free droplets (mass x_d, liquid binder x_l) by the granule points: a granule
    (x, b) becomes (x + x_d, b + x_l), so M_kl gains
      (x + x_d)^k (b + x_l)^l - x^k b^l = H_k (b + x_l)^l + x^k ((b + x_l)^l - b^l),
    H_k = (x + x_d)^k - x^k, all terms non-negative; the droplets lose what is captured."""
    n_state = config[P.N_STATE]
    nd = state[n_state - 1]
    op = off_points(n_max)
    npt = n_max * m
    counts = off_counts(n_max, m)
    props = props_view(work, n_max, m)
    xpow = off_powers(n_max, m)
    acc = off_acc(n_max, m)
    lmax = 2 * m if bivariate else 1
    n_size = 2 * n_max
    pd, bd = droplet_point(state, params, config)          # one droplet now (p_d, b_d: fresh)
    xd = pd / params[P.MASS_SCALE]
    xl = bd / params[P.MASS_SCALE]                         # the droplet's liquid binder
    drop = n_max * m
    particle_properties(pd, bd, params, config, props, drop)
    droplet_factor = params[P.NUMBER_SCALE] * params[P.DROPLET_FACTOR]
    code = config[P.KERNEL]
    captured = 0.0
    for a in range(n):
        beta = pair_collision_frequency(code, props, a * m, drop, factor, params)
        if beta == 0.0:
            continue
        beta *= droplet_factor * nd
        for q in range(2 * lmax):
            work[acc + 8 * m + q] = 0.0
        flux_a = 0.0
        for b in range(int(work[counts + a])):
            i = a * m + b
            flux = work[op + 2 * npt + i] * beta * pair_success_probability(props, i, drop, u0,
                                                                             params, config)
            flux_a += flux
            if bivariate:
                bi = work[op + npt + i]
                sb = bi + xl
                h = 0.0
                total = 1.0
                bl = 1.0
                for l in range(1, lmax):
                    h = sb * h + xl * bl          # (b + x_l)^l - b^l
                    bl *= bi
                    total *= sb                   # (b + x_d)^l
                    work[acc + 8 * m + l] += flux * total
                    work[acc + 8 * m + lmax + l] += flux * h
        captured += flux_a
        xa = work[a]
        s = xa + xd
        h = 0.0
        for k in range(1, n_size):
            h = s * h + xd * work[xpow + a * n_size + k - 1]
            out[k] += flux_a * h
            if bivariate and k < n_max:
                for l in range(1, lmax):
                    out[mixed_index(n_max, k, l)] += (h * work[acc + 8 * m + l]
                                                       + work[xpow + a * n_size + k]
                                                       * work[acc + 8 * m + lmax + l])
        if bivariate:
            for l in range(1, lmax):
                out[mixed_index(n_max, 0, l)] += work[acc + 8 * m + lmax + l]
    out[n_state - 1] -= captured
    return captured


@nb.njit(cache=True, error_model="numpy")
def _breakage(out, state, work, n_max, m, n, cell, params, config, bivariate):
    """Breakage birth and death (``physics.breakage``; binder splits in proportion to mass, so
    both daughters keep the parent's fraction), S the selection at the node's mass, F the
    daughter rule's moment factor.

    Size moments, by quadrature over the size nodes (which reproduce every M_k0, k < 2 N1):

        dM_k0/dt = sum_a w_a S(x_a) (F(k) - 1) x_a^k.

    Mixed moments (l >= 1), as a relative rate: the carried moment times the mean selection
    over the N1 x N2 points (x_a, b_ab), weights w_a r_ab, weighted by the moment's integrand,

        dM_kl/dt = (F(k + l) - 1) M_kl <S>_kl,
        <S>_kl = sum_ab w_a r_ab S(x_a) x_a^k b_ab^l / sum_ab w_a r_ab x_a^k b_ab^l

    (where no point holds binder: the size nodes' mean selection weighted by x_a^k). For a
    state the points reproduce, this is their quadrature sum_ab w_a r_ab S (F - 1) x^k b^l, the
    source of a real population; it is exact for every carried moment under a constant
    selection, and since F(k + l) < 1 for k + l >= 2 a mixed moment decays at most at the
    largest selection rate: it can never be driven below zero. The quadrature sum itself can:
    where a size node sits on a binder bound the Vandermonde shares of the other nodes need not
    be realizable, and their points may then hold far more of M_kl than the state (measured:
    collisional selection next to dry fragments, N1 = N2 = 2, alpha 0.4, Theta = 1 m2/s2 with
    droplets sprayed in: the points held 650 times the carried M03, the source took M03 below
    zero within 5 ms and the step fell to its floor; the raw Vandermonde conditional moments
    instead are not realizable at all, a negative <y^3> on a node, and put M03 60% below its
    exact value under power selection). F(1) = 1: M10 and M01 get exactly nothing (skipped,
    not summed to zero). Free droplets never break."""
    factor = cell_selection_factor(cell, params, config)
    if factor == 0.0:
        return
    code = config[P.BREAKAGE_DAUGHTERS]
    n_size = 2 * n_max
    op = off_points(n_max)
    npt = n_max * m
    counts = off_counts(n_max, m)
    acc = off_acc(n_max, m)
    sel = work[acc:acc + n_max]                          # S(x_a) per size node
    any_break = False
    for a in range(n):
        xa = work[a]
        sel[a] = node_selection_rate(xa, factor, params, config)
        if sel[a] == 0.0:
            continue
        any_break = True
        power = work[n_max + a] * sel[a]                 # w S x^k
        for k in range(n_size):
            if k != 1:
                out[k] += power * (daughter_moment_factor(code, float(k)) - 1.0)
            power *= xa
    if not bivariate or not any_break:
        return
    for l in range(1, 2 * m):
        for k in range(n_max):
            if k + l == 1:
                continue
            i = mixed_index(n_max, k, l)
            if state[i] == 0.0:
                continue
            num = 0.0
            den = 0.0
            for a in range(n):
                xk = work[a] ** k
                moment = 0.0                             # sum_b w_a r_ab b_ab^l
                for b in range(int(work[counts + a])):
                    j = a * m + b
                    moment += work[op + 2 * npt + j] * work[op + npt + j] ** l
                num += sel[a] * xk * moment
                den += xk * moment
            if not (den > 0.0):                          # no binder on any point
                for a in range(n):
                    xk = work[n_max + a] * work[a] ** k
                    num += sel[a] * xk
                    den += xk
            if den > 0.0:
                out[i] += (daughter_moment_factor(code, float(k + l)) - 1.0) * state[i] * (
                    num / den)


@nb.njit(cache=True, error_model="numpy")
def _drying(out, state, work, n_max, m, n, gas, params, config, bivariate):
    """Drying drift of the points (scaled moments per s) in the cell's ``gas``
    (``physics.drying.cell_gas``): a point (x, b) of weight w loses liquid at e(x, b)
    (``quadrature.drying_sources.point_drying_rate``, b clipped to [0, x]), so M_kl gains
    G_kl = -sum w e (k x^(k-1) b^l + l x^k b^(l-1)) and the evaporated liquid (entry
    N_STATE - 1 - SEPARATE_DROPLETS) sum w e.

    The points are the nodes' conditional points, except at a node whose conditional set lies
    within H^2 of the degenerate boundary (a near-monodisperse binder,
    ``conditional.continued_fraction_points``): there the centre and the continued pair, so the
    drift is smooth across that boundary. The size moments, M10 and M01 take G_kl as it is (the
    points reproduce them exactly, so M10 + E and M01 + E stay invariant); every other mixed
    moment takes its carried value times the points' relative rate, M_kl G_kl / sum w x^k b^l
    (as ``_breakage``): the same where the points reproduce M_kl, and a carried moment the
    points do not reproduce (the closure's gap, ``cqmom_realizable``) then decays with its own
    value instead of being driven through zero by a drift it does not hold (the falling rate is
    linear in b)."""
    op = off_points(n_max)
    npt = n_max * m
    counts = off_counts(n_max, m)
    oc = off_cond(n_max, m)
    evaporated = evaporated_entry(config)
    lmax = 2 * m if bivariate else 1
    # the inversion's scratch (not part of its memo): G_kl and sum w x^k b^l in state order,
    # then the continued points' fractions and weights
    n_mom = config[P.N_STATE] - tail_entries(config)
    s = off_scratch(n_max, m)
    gain = work[s:s + n_mom]
    held = work[s + n_mom:s + 2 * n_mom]
    ys = work[s + 2 * n_mom:s + 2 * n_mom + 3]
    rs = work[s + 2 * n_mom + 3:s + 2 * n_mom + 6]
    for i in range(n_mom):
        gain[i] = 0.0
        held[i] = 0.0
    for a in range(n):
        row = oc + a * 2 * m
        cnt = 0
        if bivariate and m > 1 and work[counts + n_max + a] == FREE:
            cnt = continued_fraction_points(work[row + 1], work[row + 2], ys, rs)
        continued = cnt > 0
        if not continued:
            cnt = int(work[counts + a])
        for q in range(cnt):
            if continued:
                x = work[a]
                b = ys[q] * x
                w = work[n_max + a] * rs[q]
            else:
                i = a * m + q
                x = work[op + i]
                b = min(max(work[op + npt + i], 0.0), x)
                w = work[op + 2 * npt + i]
            rate = w * point_drying_rate(x, b, gas, params)
            out[evaporated] += rate
            for l in range(lmax):
                for k in range(2 * n_max if l == 0 else n_max):
                    i = k if l == 0 else mixed_index(n_max, k, l)
                    gain[i] += drift_moment_rate(k, l, x, b, rate)
                    held[i] += w * x ** k * b ** l
    for l in range(lmax):
        for k in range(2 * n_max if l == 0 else n_max):
            i = k if l == 0 else mixed_index(n_max, k, l)
            if l == 0 or (k == 0 and l == 1):
                out[i] += gain[i]
            elif held[i] > 0.0:
                out[i] += state[i] * (gain[i] / held[i])


@nb.njit(cache=True, error_model="numpy")
def cqmom_rhs(state, out, cell, aux, params, config, work):
    """d(state)/dt of one cell [scaled moments per s] (layout in the module docstring).

    cell: (alpha [-], theta [m2/s2], collision velocity [m/s], injection [droplets/(m3 s)]);
    work: float array of at least ``work_size(N1, N2)``. No allocation.
    """
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    bivariate = config[P.BIVARIATE] == 1
    separate = config[P.SEPARATE_DROPLETS] == 1
    n_state = config[P.N_STATE]
    for k in range(n_state):
        out[k] = 0.0
    n = invert_cached(state, config, work)
    u0 = cell[P.COLLISION_VELOCITY]
    factor = 0.0
    if n > 0:
        d43 = _fill_properties(work, n_max, m, n, params, config)
        factor = kernel_cell_factor(config[P.KERNEL], cell[P.ALPHA], cell[P.THETA], d43, params)
    if factor != 0.0:
        _aggregation(out, work, n_max, m, n, factor, u0, params, config, bivariate)
    if n > 0 and config[P.BREAKAGE] == 1:
        _breakage(out, state, work, n_max, m, n, cell, params, config, bivariate)
    if n > 0 and config[P.DRYING] == 1:
        _drying(out, state, work, n_max, m, n, cell_gas(cell, params, config), params,
                config, bivariate)
    inj = cell[P.INJECTION] / params[P.NUMBER_SCALE]
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    xl = droplet_liquid(params) / params[P.MASS_SCALE]
    if separate:
        captured = 0.0
        pd, bd = droplet_point(state, params, config)
        if (state[n_state - 1] > 0.0 and factor != 0.0 and n > 0
                and (pd > 0.0 or droplet_liquid_entry(config) < 0)):
            captured = _droplet_capture(out, state, work, n_max, m, n, factor, u0, params,
                                        config, bivariate)
        out[n_state - 1] += inj
        add_droplet_class_terms(state, out, inj, captured, bd / params[P.MASS_SCALE],
                                cell_gas(cell, params, config), params, config)
    elif inj != 0.0:
        # droplets as ordinary particles: S_kl = rate x_d^k x_l^l
        value = inj
        for k in range(2 * n_max):
            out[k] += value
            value *= xd
        if bivariate:
            for l in range(1, 2 * m):
                value = inj * xl ** l
                for k in range(n_max):
                    out[mixed_index(n_max, k, l)] += value
                    value *= xd
