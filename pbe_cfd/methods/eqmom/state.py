"""EQMOM of one cell (gamma or lognormal kernels): state layout, work layout, inversion with
binder per kernel.

State of one cell (scaled like QMOM's: SI moment / (N_ref p_ref^(i+j))):

    [M_00, M_10, ..., M_(2N)0]          size moments, 2N + 1 entries (N kernels)
    [M_01, M_11, ..., M_(N-1)1]         binder-weighted moments (bivariate only), N entries
    [n_d]                               free droplets (only with separate droplets)

Binder per kernel: every granule of kernel a holds the binder fraction y_a (binder in
proportion to mass inside a kernel, as breakage leaves it), so M_k1 = sum_a w_a y_a mu_a,(k+1),
mu_a,k the k-th moment of the kernel (``gamma_inversion.family_moment``): N linear equations for the
N fractions, solved with 0 <= y_a <= 1 enforced (active set). At sigma = 0 this is QMOM's
binder per node (b_a = y_a x_a). The kernels' secondary rules (gamma: Gauss rules,
``inversion.gamma_rule``; lognormal: Gauss-Hermite in ln x, ``lognormal_kernels``;
aux[AUX_SECONDARY] nodes each) give the weighted particles (X, W, B = y_a X) the sources
integrate over.

aux (``aux_array``): [secondary nodes per kernel, kernel family, (lognormal) Gauss-Hermite
points and weights]. Work: ``work_size``; the result slots at its front.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.kernels import kernel_small_size_exponent
from ...physics.properties import N_PROPS
import pbe_cfd.methods.quadrature.gamma_inversion as I
import pbe_cfd.methods.quadrature.lognormal_kernels as L

#: aux slot: secondary Gauss nodes per kernel
AUX_SECONDARY = 0
#: aux slot: the kernel family (I.GAMMA, I.LOGNORMAL; an aux without it: gamma)
AUX_FAMILY = 1
#: aux slots of the lognormal kernels' Gauss-Hermite rule: n points, then n weights
AUX_HERMITE = 2
#: the most secondary particles per kernel (gamma: I.MAX_SECONDARY; lognormal: L.MAX_HERMITE)
MAX_PER_KERNEL = max(I.MAX_SECONDARY, L.MAX_HERMITE)
#: re-projection mismatch (relative) up to which a reduced fit still represents the state
PROJECTION_TOLERANCE = 1.0e-8
#: binder moments reproduced by the bounded fractions within this share of M_(k+1)0 (QMOM's
#: BINDER_TOLERANCE, for the same reason: kernels of tiny weight fix their binder only to
#: ~1e-6 of the moment)
BINDER_TOLERANCE = 1.0e-6

# ---- result slots (front of work) -------------------------------------------------------------
SIGMA = 0          # kernel width sigma (gamma: scaled mass; lognormal: of ln x, [-])
STATUS = 1         # inversion.FIT, DISCRETE, ...
KERNELS = 2        # kernel count n
TARGET = 3         # J at the result
PARTICLES = 4      # secondary particles (X, W, B) in use
HEADER = 5

_MEMO_TAG = -3.817205914672215e-213


@nb.njit(cache=True, inline="always")
def off_nodes(n_max):
    return HEADER


@nb.njit(cache=True, inline="always")
def off_weights(n_max):
    return HEADER + n_max


@nb.njit(cache=True, inline="always")
def off_fraction(n_max):
    return HEADER + 2 * n_max


@nb.njit(cache=True, inline="always")
def off_particles(n_max):
    """X at [o, o + M), W at [o + M, o + 2M), B at [o + 2M, o + 3M), M = n_max MAX_SECONDARY."""
    return HEADER + 3 * n_max


@nb.njit(cache=True, inline="always")
def max_particles(n_max):
    return n_max * MAX_PER_KERNEL


@nb.njit(cache=True, inline="always")
def off_props(n_max):
    return off_particles(n_max) + 3 * max_particles(n_max)


@nb.njit(cache=True, inline="always")
def off_scratch(n_max):
    return off_props(n_max) + (max_particles(n_max) + 1) * N_PROPS


@nb.njit(cache=True, inline="always")
def off_memo(n_max):
    return off_scratch(n_max) + I.work_length(n_max, I.MAX_SECONDARY) + 4 * n_max * n_max + 16


@nb.njit(cache=True)
def work_size(n_max, n_state):
    """Floats of work the EQMOM functions need for n_max kernels and n_state entries."""
    return off_memo(n_max) + 4 + n_state


def state_length(nodes, bivariate, separate_droplets, drying=False):
    """Number of entries of one cell's EQMOM state (N kernels)."""
    return (2 * nodes + 1 + (nodes if bivariate else 0) + (1 if drying else 0)
            + (1 if separate_droplets else 0) + (1 if drying and separate_droplets else 0))


def state_names(nodes, bivariate, separate_droplets, drying=False):
    """Names of the state entries: 'M{i}{j}', 'droplet_liquid' and 'evaporated_liquid' (with
    drying, as QMOM), then 'droplet_number_density'."""
    names = [f"M{k}0" for k in range(2 * nodes + 1)]
    if bivariate:
        names += [f"M{k}1" for k in range(nodes)]
    if drying and separate_droplets:
        names.append("droplet_liquid")
    if drying:
        names.append("evaporated_liquid")
    if separate_droplets:
        names.append("droplet_number_density")
    return names


def secondary_nodes(nodes, kernel="gamma"):
    """Secondary Gauss nodes per kernel for N kernels. Gamma: N + 2, the fewest that integrate
    the sum kernel's sources of M_2N (degree 2N + 1) and the power-law selection with a = 2
    (degree 2N + 2) exactly over the reconstruction. Lognormal: Gauss-Hermite in ln x, exact
    for no moment: L.MAX_HERMITE = 20, whose error on the moment of order q of a kernel,
    that of the rule on e^(q sigma t), is below 1e-7 up to q sigma = 4 (the sources of M_2N
    use q <= 2N + 2; the fits have sigma <= 0.7; docs/physics.md section 16)."""
    if kernel == "lognormal":
        return L.MAX_HERMITE
    return min(nodes + 2, I.MAX_SECONDARY)


def aux_array(nodes, kernel="gamma"):
    """The EQMOM's aux: [secondary nodes per kernel, family] and, for lognormal kernels, the
    Gauss-Hermite points and weights of ``lognormal_kernels.hermite_rule``."""
    n_sec = secondary_nodes(nodes, kernel)
    if kernel != "lognormal":
        return np.array([float(n_sec), float(I.GAMMA)])
    points, weights = np.zeros(n_sec), np.zeros(n_sec)
    if not L.hermite_rule(n_sec, points, weights, np.zeros(2 * n_sec)):
        raise RuntimeError(f"Gauss-Hermite rule of {n_sec} nodes did not converge")
    order = np.argsort(points)
    return np.concatenate([[float(n_sec), float(I.LOGNORMAL)], points[order], weights[order]])


@nb.njit(cache=True, inline="always")
def kernel_family(aux):
    """The kernel family of an EQMOM aux (I.GAMMA where aux has no family slot)."""
    return int(aux[AUX_FAMILY]) if aux.shape[0] > AUX_FAMILY else I.GAMMA


@nb.njit(cache=True, error_model="numpy")
def _solve_dense(mat, rhs, sol, n, w):
    """Solve mat[k, a] sol[a] = rhs[k] (n x n, row-major in ``mat``) by Gaussian elimination
    with partial pivoting in the scratch ``w`` (length >= n (n + 1)). False if singular."""
    c = n + 1
    for k in range(n):
        for a in range(n):
            w[k * c + a] = mat[k * n + a]
        w[k * c + n] = rhs[k]
    for col in range(n):
        piv = col
        big = abs(w[col * c + col])
        for r in range(col + 1, n):
            if abs(w[r * c + col]) > big:
                big = abs(w[r * c + col])
                piv = r
        if not (big > 0.0):
            return False
        if piv != col:
            for j in range(c):
                tmp = w[col * c + j]
                w[col * c + j] = w[piv * c + j]
                w[piv * c + j] = tmp
        for r in range(col + 1, n):
            f = w[r * c + col] / w[col * c + col]
            if f != 0.0:
                for j in range(col, c):
                    w[r * c + j] -= f * w[col * c + j]
    for r in range(n - 1, -1, -1):
        acc = w[r * c + n]
        for j in range(r + 1, n):
            acc -= w[r * c + j] * sol[j]
        sol[r] = acc / w[r * c + r]
    return True


@nb.njit(cache=True, error_model="numpy")
def solve_fractions(binder_moments, nodes, weights, sigma, n, frac, scratch, family=I.GAMMA):
    """Binder fraction y_a per kernel with 0 <= y_a <= 1 from the binder moments M_k1, k < n
    (scaled; ``binder_moments`` indexable 0..n-1), the kernels' centres, weights and width
    (``family``: I.GAMMA or I.LOGNORMAL).
    Active set: the free kernels solve the first n_free equations less what the bounded ones
    hold; a fraction leaving [0, 1] is put on that bound and the rest solved again. Rows are
    scaled by mean^(k+1). Returns the number of bounded kernels."""
    total = 0.0
    mass = 0.0
    for a in range(n):
        total += weights[a]
        mass += weights[a] * nodes[a]
    mean = mass / total
    fixed = scratch[0:n]
    idx = scratch[n:2 * n]
    rhs = scratch[2 * n:3 * n]
    sol = scratch[3 * n:4 * n]
    mat = scratch[4 * n:4 * n + n * n]
    w = scratch[4 * n + n * n:]
    for a in range(n):
        fixed[a] = 0.0
        frac[a] = 0.0
    for _ in range(n + 1):
        n_free = 0
        for a in range(n):
            if fixed[a] == 0.0:
                idx[n_free] = a
                n_free += 1
        if n_free == 0:
            break
        scale = mean
        for k in range(n_free):
            value = binder_moments[k]
            for a in range(n):
                if fixed[a] != 0.0:
                    value -= (weights[a] * I.family_moment(nodes[a], sigma, k + 1, family)
                              * frac[a])
            rhs[k] = value / scale
            for f in range(n_free):
                a = int(idx[f])
                mu = I.family_moment(nodes[a], sigma, k + 1, family)
                mat[k * n_free + f] = weights[a] * mu / scale
            scale *= mean
        if not _solve_dense(mat, rhs, sol, n_free, w):
            share = 0.0
            for f in range(n_free):
                a = int(idx[f])
                share += weights[a] * nodes[a]
            for f in range(n_free):
                a = int(idx[f])
                frac[a] = min(max(rhs[0] * mean / share, 0.0), 1.0) if share > 0.0 else 0.0
            break
        violated = False
        for f in range(n_free):
            a = int(idx[f])
            if sol[f] < 0.0:
                frac[a] = 0.0
                fixed[a] = 1.0
                violated = True
            elif sol[f] > 1.0:
                frac[a] = 1.0
                fixed[a] = 1.0
                violated = True
            else:
                frac[a] = sol[f]
        if not violated:
            break
    count = 0
    for a in range(n):
        if fixed[a] != 0.0:
            count += 1
    return count


@nb.njit(cache=True, error_model="numpy")
def invert(state, aux, config, work):
    """Kernels, binder fractions and secondary particles of one cell's state into the result
    slots of ``work`` (scaled units). Returns the kernel count (0: empty or not invertible;
    work[STATUS] says which)."""
    n_max = config[P.ORDER]
    n_sec = int(aux[AUX_SECONDARY])
    nodes = work[off_nodes(n_max):off_nodes(n_max) + n_max]
    weights = work[off_weights(n_max):off_weights(n_max) + n_max]
    frac = work[off_fraction(n_max):off_fraction(n_max) + n_max]
    scratch = work[off_scratch(n_max):off_memo(n_max)]
    work[SIGMA] = 0.0
    work[KERNELS] = 0.0
    work[PARTICLES] = 0.0
    work[TARGET] = 0.0
    for a in range(n_max):
        nodes[a] = 0.0
        weights[a] = 0.0
        frac[a] = 0.0
    m0 = state[0]
    if m0 == 0.0:
        work[STATUS] = I.EMPTY
        return 0
    mean = state[1] / m0 if m0 > 0.0 else 0.0
    if not (m0 > 0.0 and mean > 0.0 and math.isfinite(m0) and math.isfinite(mean)):
        work[STATUS] = I.FAILED
        return 0
    u = scratch[0:2 * n_max + 1]
    result = scratch[2 * n_max + 1:2 * n_max + 3]
    inv_work = scratch[2 * n_max + 3:]
    scale = 1.0
    for k in range(2 * n_max + 1):
        u[k] = state[k] / (m0 * scale)
        if not math.isfinite(u[k]):
            work[STATUS] = I.FAILED
            return 0
        scale *= mean
    family = kernel_family(aux)
    # a gamma kernel of shape below the aggregation kernel's small-size exponent has infinite
    # sources: the inversion does not use such a fit (docs/physics.md, EQMOM); a lognormal
    # kernel has every power moment finite (0: the fallbacks on, every kernel usable)
    min_shape = 0.0 if family == I.LOGNORMAL else kernel_small_size_exponent(config[P.KERNEL])
    status, n = I.invert_normalised(u, n_max, nodes, weights, inv_work, result, min_shape,
                                    family)
    work[STATUS] = status
    if n == 0:
        return 0
    sigma = result[0] if family == I.LOGNORMAL else result[0] * mean
    work[SIGMA] = sigma
    work[TARGET] = result[1]
    work[KERNELS] = n
    for a in range(n):
        nodes[a] *= mean
        weights[a] *= m0
    for a in range(n, n_max):
        nodes[a] = 0.0
        weights[a] = 0.0
    if config[P.BIVARIATE] == 1:
        solve_fractions(state[2 * n_max + 1:], nodes, weights, sigma, n, frac, inv_work,
                        family)
    if family == I.LOGNORMAL:
        fill_lognormal_particles(work, n_max, n, n_sec, sigma, aux)
    else:
        fill_particles(work, n_max, n, n_sec, sigma, inv_work)
    return n


@nb.njit(cache=True, inline="always")
def _centre_particle(work, o, m_max, count, node, weight, fraction):
    """Write one secondary particle at a kernel's centre (its sigma = 0) as particle
    ``count`` of the (X, W, B) block at work[o]; return the next count."""
    work[o + count] = node
    work[o + m_max + count] = weight
    work[o + 2 * m_max + count] = fraction * node
    return count + 1


@nb.njit(cache=True, error_model="numpy")
def fill_particles(work, n_max, n, n_sec, sigma, scratch):
    """The secondary particles (X, W, B) of the n kernels in ``work``: n_sec Gauss nodes of
    each kernel (one node at its centre where sigma = 0)."""
    nodes = work[off_nodes(n_max):off_nodes(n_max) + n_max]
    weights = work[off_weights(n_max):off_weights(n_max) + n_max]
    frac = work[off_fraction(n_max):off_fraction(n_max) + n_max]
    o = off_particles(n_max)
    m_max = max_particles(n_max)
    pts = scratch[0:n_sec]
    wts = scratch[n_sec:2 * n_sec]
    rule = scratch[2 * n_sec:4 * n_sec]
    count = 0
    for a in range(n):
        shape = nodes[a] / sigma if sigma > 0.0 else math.inf
        if sigma > 0.0 and math.isfinite(shape) and n_sec > 1 and \
                I.gamma_rule(shape, n_sec, pts, wts, rule):
            for j in range(n_sec):
                x = sigma * pts[j]
                work[o + count] = x
                work[o + m_max + count] = weights[a] * wts[j]
                work[o + 2 * m_max + count] = frac[a] * x
                count += 1
        else:
            count = _centre_particle(work, o, m_max, count, nodes[a], weights[a], frac[a])
    work[PARTICLES] = count


@nb.njit(cache=True, error_model="numpy")
def fill_lognormal_particles(work, n_max, n, n_sec, sigma, aux):
    """The secondary particles (X, W, B) of n lognormal kernels of log-width sigma in
    ``work``: x_a exp(sigma t_j) of weight w_a h_j, (t_j, h_j) the Gauss-Hermite rule in aux
    (``aux_array``); one node at the centre where sigma = 0."""
    nodes = work[off_nodes(n_max):off_nodes(n_max) + n_max]
    weights = work[off_weights(n_max):off_weights(n_max) + n_max]
    frac = work[off_fraction(n_max):off_fraction(n_max) + n_max]
    o = off_particles(n_max)
    m_max = max_particles(n_max)
    count = 0
    for a in range(n):
        if sigma > 0.0 and n_sec > 1:
            for j in range(n_sec):
                x = nodes[a] * math.exp(sigma * aux[AUX_HERMITE + j])
                work[o + count] = x
                work[o + m_max + count] = weights[a] * aux[AUX_HERMITE + n_sec + j]
                work[o + 2 * m_max + count] = frac[a] * x
                count += 1
        else:
            count = _centre_particle(work, o, m_max, count, nodes[a], weights[a], frac[a])
    work[PARTICLES] = count


@nb.njit(cache=True, error_model="numpy")
def invert_work(state, aux, config, work):
    """``invert``, remembered: a call with a bit-identical state, key and result slots
    reuses the last inversion (the integrator checks a stage and then evaluates its RHS)."""
    n_max = config[P.ORDER]
    n_state = config[P.N_STATE]
    key = float(kernel_family(aux) * 100000000 + n_state * 100000 + n_max * 1000
                + config[P.BIVARIATE] * 100 + int(aux[AUX_SECONDARY]))
    c = off_memo(n_max)
    s0 = c + 4
    if work[c] == _MEMO_TAG and work[c + 1] == key:
        same = True
        for k in range(n_state):
            if work[s0 + k] != state[k]:
                same = False
                break
        if same and work[c + 3] == _checksum(work, off_props(n_max)):
            return int(work[c + 2])
    n = invert(state, aux, config, work)
    work[c] = _MEMO_TAG
    work[c + 1] = key
    work[c + 2] = n
    work[c + 3] = _checksum(work, off_props(n_max))
    for k in range(n_state):
        work[s0 + k] = state[k]
    return n


@nb.njit(cache=True, inline="always")
def _checksum(work, count):
    total = 0.0
    for i in range(count):
        total += work[i] * (i + 1.5)
    return total


def kernels_of(state, config, aux):
    """Python helper: (sigma, centres x_a, weights w_a, binder fractions y_a, status) of one
    cell's scaled state (scaled units; arrays of the kernel count)."""
    n_max = int(config[P.ORDER])
    work = np.zeros(work_size(n_max, int(config[P.N_STATE])))
    n = invert(np.ascontiguousarray(state, dtype=np.float64), np.asarray(aux, float), config,
               work)
    x = work[off_nodes(n_max):off_nodes(n_max) + n].copy()
    w = work[off_weights(n_max):off_weights(n_max) + n].copy()
    y = work[off_fraction(n_max):off_fraction(n_max) + n].copy()
    return float(work[SIGMA]), x, w, y, int(work[STATUS])


def particles_of(state, config, aux):
    """Python helper: the secondary particles (X, W, B) of one cell's scaled state."""
    n_max = int(config[P.ORDER])
    work = np.zeros(work_size(n_max, int(config[P.N_STATE])))
    invert(np.ascontiguousarray(state, dtype=np.float64), np.asarray(aux, float), config, work)
    m = int(work[PARTICLES])
    o, mm = off_particles(n_max), max_particles(n_max)
    return (work[o:o + m].copy(), work[o + mm:o + mm + m].copy(),
            work[o + 2 * mm:o + 2 * mm + m].copy())
