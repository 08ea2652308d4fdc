"""Conditional moments and their quadrature on [0, 1] (the inner step of CQMOM).

Conditional quadrature (Yuan and Fox 2011, J. Comput. Phys. 230, 8216) inverts a bivariate
moment set in two steps: a Gauss rule in the first variable (here the granule mass p: nodes
p_a, weights w_a) from the pure moments M_k0, then, per node, a Gauss rule in the second
variable from the *conditional* moments, recovered from the mixed moments by a Vandermonde solve

    M_kl = sum_a w_a p_a^k <b^l>_a,        k < n (one system per l, the same matrix for all l).

Here the second variable is the binder fraction y = b / p in [0, 1]: at a node the mass is
fixed, so <y^l>_a = <b^l>_a / p_a^l. Its support is bounded and the same at every node, so

* b <= p holds at every node by construction (Gauss nodes lie in the support's hull);
* realizability is the Hausdorff condition on [0, 1], tested by where the nodes fall;
* a set that is not realizable has a nearest realizable one in closed form (a principal
  representation with an atom on 0 or 1, or fewer nodes), so the inversion never fails;
* y is O(1) whatever the node's mass (1e-12 .. 1e-6 kg), so tolerances are scale-free.

All quantities are non-dimensional (scaled moments, nodes and weights; y is a fraction).
Functions write into preallocated arrays and never allocate.
"""
import math

import numba as nb

from ..quadrature.drying_sources import CONTINUE_SPREAD, continued_pair_share
from ..quadrature.gauss import DEGENERACY_TOLERANCE, solve_vandermonde, wheeler_nodes

#: The conditional mean binder fraction of a node fixed on a bound by the bounded solve is
#: exactly 0 or 1; these flags in ``fixed`` say which.
FREE = 0.0
ON_BOUND = 1.0


@nb.njit(cache=True, inline="always")
def _one_node(mean, nodes, weights):
    nodes[0] = mean
    weights[0] = 1.0
    return 1


@nb.njit(cache=True, error_model="numpy")
def gauss2_unit_interval(mu1, mu2, mu3, nodes, weights):
    """Two-node rule of the fraction moments (1, mu1, mu2, mu3) on [0, 1]; returns the count.

    * variance mu2 - mu1^2 not above DEGENERACY_TOLERANCE mu2 (or mu1 on 0 or 1): one node at
      mu1 (a degenerate set, or the nearest realizable one if the variance is negative);
    * mu2 >= mu1 (the largest second moment [0, 1] allows): atoms on 0 and 1 (keeps mu1);
    * otherwise the Gauss rule; if a node leaves [0, 1], mu3 lies outside its realizable range
      for (mu1, mu2) and the rule is the principal representation on that side: atoms on 0 and
      mu2 / mu1 (lower), or on (mu1 - mu2) / (1 - mu1) and 1 (upper), which keep mu1 and mu2.
    Weights sum to 1; nodes are written in [0, 1].
    """
    if not (mu1 > 0.0) or not (mu1 < 1.0):
        return _one_node(min(max(mu1, 0.0), 1.0), nodes, weights)
    var = mu2 - mu1 * mu1
    if not (var > DEGENERACY_TOLERANCE * mu2):
        return _one_node(mu1, nodes, weights)
    if mu2 >= mu1:
        nodes[0] = 0.0
        nodes[1] = 1.0
        weights[0] = 1.0 - mu1
        weights[1] = mu1
        return 2
    third = mu3 - mu1 * (3.0 * mu2 - 2.0 * mu1 * mu1)      # third central moment
    q = third / var
    centre = mu1 + 0.5 * q
    half = math.sqrt(0.25 * q * q + var)
    if centre >= 0.0:
        upper = centre + half
        lower = (mu1 * (mu1 + q) - var) / upper if upper > 0.0 else centre - half
    else:
        lower = centre - half
        upper = (mu1 * (mu1 + q) - var) / lower
    if math.isfinite(lower) and math.isfinite(upper) and lower >= 0.0 and upper <= 1.0:
        nodes[0] = lower
        nodes[1] = upper
        weights[1] = (mu1 - lower) / (upper - lower)
        weights[0] = 1.0 - weights[1]
        return 2
    if not (lower >= 0.0):
        # mu3 below its range: atoms on 0 and mu2/mu1 (weight there mu1^2/mu2)
        nodes[0] = 0.0
        nodes[1] = mu2 / mu1
        weights[1] = mu1 * mu1 / mu2
        weights[0] = 1.0 - weights[1]
        return 2
    # mu3 above its range: atoms on (mu1 - mu2)/(1 - mu1) and 1 (weight there var/((1-mu1)^2+var))
    one_minus = 1.0 - mu1
    nodes[0] = (mu1 - mu2) / one_minus
    nodes[1] = 1.0
    weights[1] = var / (one_minus * one_minus + var)
    weights[0] = 1.0 - weights[1]
    return 2


@nb.njit(cache=True, error_model="numpy")
def continued_fraction_points(mu1, mu2, ys, rs):
    """Points of a conditional set near the degenerate boundary, for the drift (docs/physics.md
    section 15, "CQMOM's drift near a monodisperse binder"): where the variance v = mu2 - mu1^2
    of the binder fraction lies below H^2, H = min(CONTINUE_SPREAD mu1, 1 - mu1), the pair
    mu1 -+ H of weight t / 2 each and the point mu1 of weight 1 - t, t = v / H^2 down to
    t = -1/2 and -1/2 + tanh(2 t + 1) / 2 below (carried moments outside the realizable set: a
    negative weight on the pair, above -1; value and two derivatives continuous at -1/2).
    Returns 3 (ys, rs in increasing ys), or 0 where v >= H^2 or mu1 is not inside (0, 1): the
    node's own rule applies.

    Every sum over these points is the centre's plus t times the pair's excess, linear in v
    from -H^2 / 2 to H^2, so it reproduces mu0, mu1, mu2 there, and twice differentiable in the
    state across v = 0, the boundary a monodisperse binder sits on. A step's stage lands
    outside it (by (h e / 2 p)^2 from the constant-rate closed form); the one-point rule there
    would put the gap into the drift's relative rates, and the two-node rule just inside reads
    the noise of mu3 (nodes c + q / 2 -+ (q^2 / 4 + v)^(1/2), q = third central moment / v)."""
    if not (mu1 > 0.0) or not (mu1 < 1.0):
        return 0
    h = min(CONTINUE_SPREAD * mu1, 1.0 - mu1)
    var = mu2 - mu1 * mu1
    if not (var < h * h) or not (h * h > 0.0):
        return 0
    t = continued_pair_share(var, h, -0.5)   # linear to -1/2, held above -1 below
    ys[0] = mu1 - h
    ys[1] = mu1
    ys[2] = mu1 + h
    rs[0] = 0.5 * t
    rs[1] = 1.0 - t
    rs[2] = 0.5 * t
    return 3


#: A three-node rule is accepted with nodes up to this far outside [0, 1] (round-off of an atom
#: on an end point: dry granules, y = 0), and clipped onto it; beyond, the principal
#: representation with an atom on that end point.
END_POINT_SLACK = 1.0e-12


@nb.njit(cache=True, error_model="numpy")
def _principal3(mu, upper, nodes, weights):
    """Principal representation of the fraction moments mu[0:5] on [0, 1]: an atom on 0
    (``upper`` False) or on 1 (True) and the two-node rule of the moments of y dmu (of
    (1 - y) dmu), which keeps mu0 .. mu4 and moves only mu5 (the three-node analogue of the
    atoms ``gauss2_unit_interval`` puts on an end point). Returns the node count, 0 if mu0 ..
    mu4 are themselves not realizable (the caller then reduces the count)."""
    if upper:
        nu0 = 1.0 - mu[1]
        nu1 = mu[1] - mu[2]
        nu2 = mu[2] - mu[3]
        nu3 = mu[3] - mu[4]
    else:
        nu0 = mu[1]
        nu1 = mu[2]
        nu2 = mu[3]
        nu3 = mu[4]
    if not (nu0 > 0.0):
        return 0
    n = gauss2_unit_interval(nu1 / nu0, nu2 / nu0, nu3 / nu0, nodes, weights)
    rest = 1.0
    for a in range(n):
        lever = 1.0 - nodes[a] if upper else nodes[a]
        if not (lever > 0.0):
            return 0
        weights[a] = nu0 * weights[a] / lever
        rest -= weights[a]
    if rest < 0.0:
        return 0
    if rest <= DEGENERACY_TOLERANCE:   # the end point holds nothing: n atoms inside carry it
        return n
    nodes[n] = 1.0 if upper else 0.0
    weights[n] = rest
    return n + 1


@nb.njit(cache=True, error_model="numpy")
def gauss_unit_interval(mu, m, nodes, weights, work):
    """Gauss rule of at most m nodes (m <= 3) on [0, 1] of a measure of unit mass with the
    fraction moments mu[0:2m] (mu[0] = 1); returns the node count written into nodes, weights.

    m = 1: the node mu1 (clipped to [0, 1]); m = 2: ``gauss2_unit_interval``; m = 3: Wheeler
    and Golub-Welsch on the moments of z = 1 + y (so that an atom on y = 0 is an ordinary
    positive node), accepted if its three nodes lie in [0, 1] (within END_POINT_SLACK, then
    clipped); a node below 0 (above 1) means mu5 is outside its range and the rule becomes the
    principal representation with an atom on 0 (on 1), which keeps mu0 .. mu4; where even those
    are not realizable, the two-node rule of mu0 .. mu3 (the count is reduced, never NaN).
    ``work`` length >= 6 + 61 (the shifted moments, then ``quadrature.wheeler_nodes``'s work).
    """
    mu1 = mu[1]
    if m == 1 or not (mu1 > 0.0) or not (mu1 < 1.0):
        return _one_node(min(max(mu1, 0.0), 1.0), nodes, weights)
    if m >= 3:
        shifted = work[0:6]
        for l in range(6):
            value = 0.0
            binomial = 1.0
            for j in range(l + 1):
                value += binomial * mu[j]          # (1 + y)^l = sum_j C(l, j) y^j
                binomial = binomial * (l - j) / (j + 1)
            shifted[l] = value
        n = wheeler_nodes(shifted, 3, nodes, weights, work[6:])
        if n == 3:
            inside = True
            for a in range(3):
                nodes[a] -= 1.0
                if nodes[a] < -END_POINT_SLACK or nodes[a] > 1.0 + END_POINT_SLACK:
                    inside = False
                nodes[a] = min(max(nodes[a], 0.0), 1.0)
            if inside:
                return 3
        n = _nearest_principal3(mu, nodes, weights, work)
        if n > 0:
            return n
    return gauss2_unit_interval(mu1, mu[2], mu[3], nodes, weights)


@nb.njit(cache=True, error_model="numpy")
def _nearest_principal3(mu, nodes, weights, work):
    """Of the two principal representations of mu0 .. mu4 (``_principal3``: atom on 0, atom
    on 1), the one whose mu5 is nearer the given mu5; 0 if neither exists. (A node of the
    three-node rule below 0 makes Wheeler drop it, so the side cannot be read off the rule.)
    ``work`` length >= 6."""
    lower_nodes = work[0:3]
    lower_weights = work[3:6]
    n_low = _principal3(mu, False, lower_nodes, lower_weights)
    n_up = _principal3(mu, True, nodes, weights)
    if n_low == 0:
        return n_up
    miss_up = math.inf
    if n_up > 0:
        miss_up = -mu[5]
        for a in range(n_up):
            miss_up += weights[a] * nodes[a] ** 5
        miss_up = abs(miss_up)
    miss_low = -mu[5]
    for a in range(n_low):
        miss_low += lower_weights[a] * lower_nodes[a] ** 5
    if abs(miss_low) <= miss_up:
        for a in range(n_low):
            nodes[a] = lower_nodes[a]
            weights[a] = lower_weights[a]
        return n_low
    return n_up


#: The bounded per-node binder is corrected to reproduce M01 where it misses it by more than
#: this share of the binder bound M10 (beyond round-off).
BINDER_MASS_SLACK = 1.0e-13


@nb.njit(cache=True, error_model="numpy")
def restore_binder_mass(m01, n, nodes, weights, mean_binder):
    """Make the bounded per-node binder reproduce the binder mass m01 = sum_a w_a <b>_a exactly
    where 0 <= m01 <= sum_a w_a p_a allows it. An active-set solve that puts several nodes on
    their bounds at once can miss it; the residual is shared in proportion to each node's room
    (p_a - <b>_a to add, <b>_a to remove), which keeps every node within [0, p_a].
    Returns the relative change of the binder mass made (0 if none was needed)."""
    have = 0.0
    room = 0.0
    bound = 0.0
    for a in range(n):
        have += weights[a] * mean_binder[a]
        room += weights[a] * (nodes[a] - mean_binder[a])
        bound += weights[a] * nodes[a]
    residual = m01 - have
    if abs(residual) <= BINDER_MASS_SLACK * bound:
        return 0.0
    if residual > 0.0 and room > 0.0:
        f = min(residual / room, 1.0)
        for a in range(n):
            mean_binder[a] += f * (nodes[a] - mean_binder[a])
    elif residual < 0.0 and have > 0.0:
        f = min(-residual / have, 1.0)
        for a in range(n):
            mean_binder[a] -= f * mean_binder[a]
    return abs(residual) / bound


@nb.njit(cache=True, error_model="numpy")
def fraction_moments(state, start, n_size, n, nodes, weights, mean_binder, m, cond, fixed, work):
    """Conditional fraction moments <y^l>_a, l < 2m, of the n size nodes into
    cond[a * 2m + l], from the mixed moments M_kl at state[start + (l - 1) n_size + k].

    ``mean_binder`` holds the bounded per-node binder <b>_a in [0, p_a] (which reproduces M01
    exactly; see ``qmom.solve_node_binder``): <y>_a = <b>_a / p_a. The levels l >= 2 come from
    the Vandermonde systems of all n nodes (Yuan and Fox), in masses scaled by their mean; a
    node whose <b>_a lies on a bound (0 or p_a) holds a single atom y = 0 or 1 whatever its
    solved moments (``fixed[a]`` = ON_BOUND, else FREE). Solving every level with every node,
    rather than with the free nodes alone, keeps the conditional moments continuous in the
    state when a node reaches a bound: switching the set of equations made the right-hand side
    jump and the step controller chatter (measured: a step budget of 1e6 exhausted). ``work``
    length >= 4 n + n (n + 1). Coincident nodes (a singular system) get one atom each.
    """
    rhs = work[0:n]
    sol = work[n:2 * n]
    scaled = work[2 * n:3 * n]
    solve_work = work[4 * n:]
    mean_size = 0.0
    total = 0.0
    for a in range(n):
        mean_size += weights[a] * nodes[a]
        total += weights[a]
    mean_size = mean_size / total
    for a in range(n):
        y = mean_binder[a] / nodes[a]
        row = a * 2 * m
        cond[row] = 1.0
        cond[row + 1] = y
        fixed[a] = ON_BOUND if (mean_binder[a] <= 0.0 or mean_binder[a] >= nodes[a]) else FREE
        scaled[a] = nodes[a] / mean_size
    for l in range(2, 2 * m):
        base = start + (l - 1) * n_size
        scale_k = 1.0
        for k in range(n):
            rhs[k] = state[base + k] / scale_k
            scale_k *= mean_size
        solved = solve_vandermonde(scaled, rhs, sol, n, solve_work)
        for a in range(n):
            row = a * 2 * m
            if fixed[a] == ON_BOUND or not solved:
                cond[row + l] = cond[row + 1] ** l
            else:
                cond[row + l] = sol[a] / (weights[a] * nodes[a] ** l)
