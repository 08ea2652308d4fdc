"""EQMOM's own continuous size distribution, and gamma-kernel fits of other methods'
moments: per row a mixture of gamma kernels in granule mass p (``methods.eqmom``;
docs/physics.md, sections "EQMOM" and 11.1).

Row r holds kernels a of centre x_a [kg], number weight w_a [1/m3], binder fraction y_a [-],
one width sigma [kg] and a support floor s [kg] (0: the kernels live on [0, inf)). Kernel a's
number density is gamma of shape l_a = x_a / sigma and scale sigma in u = p - s; its mass
density p n_a = (s + u) n_a is the mixture s Gamma(l_a) + x_a Gamma(l_a + 1) (times w_a), so

    Q3(d) = sum_a w_a [s P(l_a, u / sigma) + x_a P(l_a + 1, u / sigma)] / sum_a w_a (s + x_a),

u = p(d) - s, P the regularised lower incomplete gamma function (s = 0: sum_a w_a x_a P(l_a +
1, p / sigma) / sum_a w_a x_a). sigma = 0 (a discrete fit) makes every kernel a step at s +
x_a. The binder fraction of a size class is the kernels' y_a weighted by their mass in the
class (exact for the per-kernel binder model). Percentiles: a row of one kernel without a
floor in closed form (the inverse of P, or its centre for sigma = 0); any other row by
bisection between the lowest and the highest percentile of its gamma components (the row's
Q3 is a mass-weighted mean of theirs, so its percentile lies between them).
A row whose inversion fell back is named in ``notes`` with the fallback.
"""
from __future__ import annotations

import numpy as np

from ..util.threads import run_shares, run_threads
from .quantiles import BISECTIONS, bisect_quantiles, check_fractions
from .reconstruct import DELTA_REL_VAR, _rows_text, diameter_of_mass, mass_of_diameter

#: Newton's method for a percentile between its components' own stops at a step below this
#: relative to the mass, or where Q3 is within Q3_ROUNDOFF of the fraction (at most
#: BISECTIONS steps)
QUANTILE_PRECISION, Q3_ROUNDOFF = 1.0e-13, 1.0e-15


class KernelMixture:
    """Rows of gamma-kernel mixtures: ``kernels`` a list per row of (sigma [kg], x [kg],
    w [1/m3], y [-], status); ``rho`` the granule density [kg/m3]; ``status_text`` the
    inversion branches' names; ``reported`` the branch codes worth a note, ``failed`` the
    code of a row without kernels; ``floor`` the support's lower end s [kg] per row (or one
    for all; None: 0)."""

    def __init__(self, kernels, rho, bivariate, status_text, reported=(), failed=None,
                 labels=str, floor=None):
        rows = len(kernels)
        n = max((len(k[1]) for k in kernels), default=0)
        x, w, y = (np.zeros((rows, n)) for _ in range(3))
        for r, (_, xr, wr, yr, _) in enumerate(kernels):
            x[r, :len(xr)], w[r, :len(xr)], y[r, :len(xr)] = xr, wr, yr
        self._set(np.array([float(k[0]) for k in kernels]), x, w, y,
                  np.array([int(k[4]) for k in kernels], dtype=int), rho, bivariate,
                  status_text, reported, failed, labels, floor)

    @classmethod
    def of_arrays(cls, sigma, x, w, y, status, rho, bivariate, status_text, reported=(),
                  failed=None, labels=str, floor=None):
        """The mixture of per-row arrays: sigma [kg] (rows,), centres x [kg], weights w
        [1/m3], binder fractions y [-] (rows, n; w = 0: no kernel), status codes (rows,);
        the other arguments as for the constructor."""
        mix = cls.__new__(cls)
        mix._set(np.asarray(sigma, float), np.asarray(x, float), np.asarray(w, float),
                 np.asarray(y, float), np.asarray(status, int), rho, bivariate, status_text,
                 reported, failed, labels, floor)
        return mix

    def _set(self, sigma, x, w, y, status, rho, bivariate, status_text, reported, failed,
             labels, floor):
        self.rho = float(rho)
        self.rows = sigma.size
        self.sigma, self.x, self.w, self.y = sigma, x, w, y
        self.bivariate = bivariate
        self.floor = np.broadcast_to(np.asarray(0.0 if floor is None else floor, float),
                                     (self.rows,)).copy()
        self.kernel_mass = np.where(self.w > 0, self.w * (self.x + self.floor[:, None]), 0.0)
        self.mass = self.kernel_mass.sum(axis=1)
        self.empty = ~(self.mass > 0)
        self.notes = []
        for code in reported:
            rows = np.flatnonzero(status == code)
            if rows.size:
                self.notes.append(f"size distribution: EQMOM inversion {status_text[code]} at "
                                  f"{_rows_text(rows, labels)}"
                                  + ("; no granules drawn, d10/d50/d90 = 0 there"
                                     if code == failed else ""))

    def _kernel_cdf(self, p, rows=slice(None), slope=False):
        """Per row (of ``rows``) and kernel the mass fraction of the kernel below p [kg]
        ((rows, k)) as (rows, n, k); ``slope``: also its derivative in p [1/kg]. With u = (p
        - s) / sigma and g = u^l e^-u / Gamma(l + 1) (the recurrence P(l, u) = P(l + 1, u) +
        g), the fraction is P(l + 1, u) + c g and its slope g (1 + c (l / u - 1)) / sigma, c
        = s / (s + x_a) the floor's share of the kernel's mean mass. Every entry is computed
        on its own, so large calls run in blocks of rows on the run's threads
        (``row_blocks``) with every number as in one block."""
        idx = np.arange(self.rows)[rows]
        p = np.broadcast_to(np.asarray(p, dtype=float), (idx.size,) + np.shape(p)[-1:])
        floored = bool(np.any(self.floor[idx] > 0))
        return in_row_blocks(
            lambda b: self._kernel_cdf_rows(p[b], idx[b], slope, floored), idx.size,
            (self.x.shape[1], p.shape[1]), 2 if slope else 1)

    def _kernel_cdf_rows(self, p, rows, slope, floored):
        """``_kernel_cdf`` of the rows ``rows`` (index array) at p [kg] (len(rows), k);
        ``floored``: whether any row of the call has a floor (the floor's term is added)."""
        from scipy.special import gammainc, gammaln
        sigma, x, s = self.sigma[rows], self.x[rows], self.floor[rows][:, None, None]
        smooth = (sigma > 0)[:, None, None]
        sig = np.where(sigma > 0, sigma, 1.0)[:, None, None]
        l = np.where(x > 0, x, 1.0)[:, :, None] / sig
        u = np.maximum(p[:, None, :] - s, 0.0) / sig
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            q = gammainc(l + 1.0, u)
            if floored or slope:
                g = np.where(u > 0, np.exp(l * np.log(u) - u - gammaln(l + 1.0)), 0.0)
                c = s / (s + l * sig)
                q = q + c * g
            step = (p[:, None, :] >= s + x[:, :, None]) * 1.0
            q = np.where(smooth, q, step)
            if not slope:
                return q
            dq = np.where(u > 0, g * (1.0 + c * (l / u - 1.0)) / sig, 0.0)
        return q, np.where(smooth, dq, 0.0)

    def cdf(self, d, rows=slice(None)):
        """Q3 [-] at diameters d [m] ((k,) or (rows, k)) per row (0 in an empty row);
        ``rows`` an index of the rows to evaluate (default all)."""
        empty, mass = self.empty[rows], self.mass[rows]
        d = np.broadcast_to(np.asarray(d, dtype=float), (empty.size,) + np.shape(d)[-1:])
        p = mass_of_diameter(d, self.rho)
        part = self._kernel_cdf(p, rows)
        num = np.einsum("rn,rnk->rk", self.kernel_mass[rows], part)
        tot = np.where(empty, 1.0, mass)[:, None]
        return np.where(empty[:, None], 0.0, num / tot)

    def kernel_quantiles(self, fractions):
        """Per row, kernel and fraction the (lowest, highest) percentile [kg] of granule mass
        of the kernel's gamma components, each (rows, n, len(fractions)): s + P^-1(l_a, f)
        sigma and s + P^-1(l_a + 1, f) sigma (without a floor both the kernel's own
        percentile P^-1(l_a + 1, f) sigma), s + x_a where sigma = 0; NaN for a kernel
        without mass. Run in blocks of rows on the run's threads as ``_kernel_cdf``."""
        f = check_fractions(fractions)
        return in_row_blocks(lambda b: self._kernel_quantiles_rows(f, b), self.rows,
                             (self.x.shape[1], f.size), 2)

    def _kernel_quantiles_rows(self, f, rows):
        """``kernel_quantiles`` of the rows ``rows`` (a slice) at the fractions f."""
        from scipy.special import gammaincinv
        sigma, x, floor = self.sigma[rows], self.x[rows], self.floor[rows]
        sig = np.where(sigma > 0, sigma, 1.0)[:, None, None]
        s = floor[:, None, None]
        shape = np.where(x > 0, x, 1.0)[:, :, None] / sig
        hi = gammaincinv(shape + 1.0, f[None, None, :]) * sig + s
        lo = hi
        if np.any(s > 0):
            lo = np.where(s > 0, gammaincinv(shape, f[None, None, :]) * sig + s, hi)
        discrete = (sigma > 0)[:, None, None]
        lo = np.where(discrete, lo, (x + floor[:, None])[:, :, None])
        hi = np.where(discrete, hi, (x + floor[:, None])[:, :, None])
        has = (self.kernel_mass[rows] > 0)[:, :, None]
        return np.where(has, lo, np.nan), np.where(has, hi, np.nan)

    def quantiles(self, fractions):
        """Diameters [m] at the mass fractions per row (0 in an empty row): closed-form in a
        row of one kernel, else by bisection between its kernels' percentiles."""
        f = check_fractions(fractions)
        key = tuple(float(v) for v in f)
        cache = self.__dict__.setdefault("_quantile_cache", {})
        if key not in cache:
            cache[key] = self._quantiles(f)
        return cache[key].copy()

    def _quantiles(self, f):
        full = ~self.empty
        q = np.zeros((self.rows, f.size))
        if not np.any(full):
            return q
        kl, kh = (v[full] for v in self.kernel_quantiles(f))    # (full rows, n, k)
        with np.errstate(invalid="ignore"):
            lo, hi = np.nanmin(kl, axis=1), np.nanmax(kh, axis=1)
        q[full] = diameter_of_mass(lo, self.rho)
        several = np.flatnonzero(full)[np.any(hi > lo, axis=1)]
        smooth = several[self.sigma[several] > 0]
        if smooth.size:
            sub = np.isin(np.flatnonzero(full), smooth)
            q[smooth] = diameter_of_mass(self._newton(smooth, f, lo[sub], hi[sub]), self.rho)
        steps = several[~(self.sigma[several] > 0)]
        if steps.size:
            # a relative 1e-9 outside the kernels' own: a step at the top is reached
            sub = np.isin(np.flatnonzero(full), steps)
            d_lo = diameter_of_mass(lo[sub], self.rho) * (1 - 1e-9)
            d_hi = diameter_of_mass(hi[sub], self.rho) * (1 + 1e-9)
            q[steps] = bisect_quantiles(lambda d: self.cdf(d, steps), f, steps.size,
                                        lo=d_lo, hi=d_hi)
        return q

    def _newton(self, rows, f, lo, hi):
        """Masses p [kg] (len(rows), len(f)) where Q3 of the smooth ``rows`` reaches f:
        Newton's method on Q3 - f in ln u, u = p - s (Q3 ~ u^l near the floor, ~ 1 - u^l
        e^-u in the tail: both nearly linear or convex in ln u), inside the bracket [lo, hi]
        [kg] (the components' own percentiles); a bisection step (geometric in u) wherever
        Newton's would leave the bracket; until a step is below QUANTILE_PRECISION p (at most
        BISECTIONS steps), or Q3 is within Q3_ROUNDOFF of f (the round-off of Q3 near 1)."""
        s = self.floor[rows][:, None]
        weight = self.kernel_mass[rows][:, :, None] / self.mass[rows][:, None, None]

        def excess(p, slope=False):
            out = self._kernel_cdf(p, rows, slope=slope)
            q = out[0] if slope else out
            F = np.sum(weight * q, axis=1) - f[None, :]
            return (F, np.sum(weight * out[1], axis=1)) if slope else F

        a, b = lo.copy(), hi.copy()
        # a percentile within QUANTILE_PRECISION of the floor is the floor's (no root in u)
        edge = s * (1.0 + QUANTILE_PRECISION)
        at_floor = (s > 0) & (excess(np.broadcast_to(edge, a.shape)) >= 0)
        a = np.where((s > 0) & ~at_floor, np.maximum(a, edge), a)
        b = np.where(at_floor, edge, b)
        p = np.where(a > s, s + np.sqrt((a - s) * (b - s)), 0.5 * (a + b))
        for _ in range(BISECTIONS):
            F, slope = excess(p, slope=True)
            a, b = np.where(F < 0, p, a), np.where(F >= 0, p, b)
            u = p - s
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                newton = s + u * np.exp(-F / (slope * u))
            inside = (newton >= a) & (newton <= b)
            half = np.where(a > s, s + np.sqrt((a - s) * (b - s)), 0.5 * (a + b))
            done = (inside & (np.abs(newton - p) <= QUANTILE_PRECISION * p)) | (
                b - a <= QUANTILE_PRECISION * b) | (np.abs(F) <= Q3_ROUNDOFF)
            p = np.where(inside, newton, half)
            if np.all(done | at_floor):
                break
        return np.where(at_floor, edge, p)

    def class_binder(self, d_lo, d_hi):
        """Binder mass over granule mass [-] in each class [d_lo, d_hi] (rows, k)."""
        if not self.bivariate:
            return None
        rows = (self.rows,) + np.shape(d_lo)[-1:]
        p_lo = mass_of_diameter(np.broadcast_to(np.asarray(d_lo, float), rows), self.rho)
        p_hi = mass_of_diameter(np.broadcast_to(np.asarray(d_hi, float), rows), self.rho)
        dm = self.kernel_mass[:, :, None] * (self._kernel_cdf(p_hi) - self._kernel_cdf(p_lo))
        tot = dm.sum(axis=1)
        yb = np.einsum("rn,rnk->rk", self.y, dm)
        return np.where(tot > 0, yb / np.where(tot > 0, tot, 1.0), 0.0)


#: entries (rows x kernels x points) of a call below which it runs in one block (ours: about
#: 1.5 ms of special functions, against ~0.1 ms to hand a block to a thread; the bed's
#: percentile bisections evaluate every cell at three diameters, ~2e5 entries at 1e5 cells)
BLOCK_ENTRIES = 20_000


def row_blocks(rows: int, per_row: int) -> list:
    """Slices of ``rows`` rows for the run's threads (numba's thread count, ``--threads``):
    one block below BLOCK_ENTRIES entries (``per_row`` each), else one per thread."""
    threads = run_threads()
    if threads == 1 or rows * per_row < BLOCK_ENTRIES or rows < 2:
        return [slice(0, rows)]
    edges = np.linspace(0, rows, min(threads, rows) + 1).astype(int)
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def in_row_blocks(evaluate, rows: int, trailing: tuple, outputs: int = 1):
    """``evaluate(block)`` over the blocks of ``row_blocks`` of ``rows`` rows: it takes a
    slice of the rows and returns one array (or a tuple of ``outputs``) of shape (block rows,)
    + ``trailing``. On the run's threads into arrays allocated once, or one call for one
    block. ``evaluate`` must compute every row on its own (then the numbers are those of one
    block)."""
    blocks = row_blocks(rows, int(np.prod(trailing)))
    if len(blocks) == 1:
        return evaluate(blocks[0])
    out = [np.empty((rows,) + tuple(trailing)) for _ in range(outputs)]

    def block(b):
        got = evaluate(b)
        for o, g in zip(out, got if outputs > 1 else (got,)):
            o[b] = g

    run_shares(block, blocks, "cdf")
    return tuple(out) if outputs > 1 else out[0]


def of_states(states, aux, arrays, rho, bivariate, labels=str) -> KernelMixture:
    """The KernelMixture of EQMOM's scaled states (rows: times or cells); rows whose
    inversion took the fewer-kernel or the closest-sigma fallback or failed are named (a failed row has no
    kernels: no granules to draw, d10/d50/d90 = 0 there)."""
    from ..methods.eqmom import entry
    from ..methods.quadrature import gamma_inversion as inversion
    kernels = [entry.kernels_si(s, aux, arrays) for s in np.atleast_2d(states)]
    return KernelMixture(kernels, rho, bivariate, inversion.STATUS_TEXT,
                         reported=(inversion.FEWER, inversion.CLOSEST, inversion.FAILED),
                         failed=inversion.FAILED, labels=labels)


#: the branch names of ``of_nodes`` rows (after the EQMOM inversion's own)
ONE_KERNEL_FALLBACK = "not invertible with n kernels: one gamma kernel on M00, M10, M20"
DELTA_FALLBACK = "not realizable (M20 < M10^2/M00): a delta at the mean mass"
NOT_FINITE = "a node not finite: no granules drawn, d10/d50/d90 = 0 there"
BELOW_FLOOR = ("mean mass not above the support's floor: kernels on [0, inf) instead of "
               "[floor, inf)")


def _size_nodes(w_all, p_all, rows, signed=False):
    """{row: (masses [kg], number weights [1/m3])} of the distinct size nodes of each of
    ``rows`` (of the padded nodes w_all [1/m3], p_all [kg]; CQMOM's binder nodes of one size
    node merged, ``node_groups.size_nodes``), nodes with w <= 0 (``signed``: w = 0) or
    p <= 0 left out."""
    from .node_groups import size_nodes
    w, p = (np.ascontiguousarray(a[rows], dtype=float) for a in (w_all, p_all))
    x, wx = np.empty_like(p), np.empty_like(p)
    count = size_nodes(w, p, bool(signed), x, wx)
    return {r: (x[k, :count[k]], wx[k, :count[k]]) for k, r in enumerate(rows.tolist())}


def _fit_row(x, w, kernels):
    """EQMOM with ``kernels`` gamma kernels of the moments m_0 .. m_2kernels of the nodes
    (x [kg], w [1/m3]): (sigma [kg], centres [kg], weights [1/m3], status)."""
    from ..methods.quadrature import gamma_inversion as I
    m0 = w.sum()
    mean = (w * x).sum() / m0
    u = np.array([(w * (x / mean) ** k).sum() / m0 for k in range(2 * kernels + 1)])
    nodes, weights = np.zeros(kernels), np.zeros(kernels)
    work, result = np.zeros(I.work_length(kernels, 0)), np.zeros(2)
    if not np.all(np.isfinite(u)):
        return 0.0, nodes[:0], weights[:0], I.FAILED
    status, n = I.invert_normalised(u, kernels, nodes, weights, work, result)
    return result[0] * mean, nodes[:n] * mean, weights[:n] * m0, status


def of_nodes(populations, rho, bivariate, labels=str, floor=0.0, kernels=None,
             signed=False) -> KernelMixture:
    """Per row the gamma EQMOM of n kernels of one width on the support [floor, inf) fitted
    to the moments of p - floor that the row's population carries exactly
    (docs/physics.md section 11.1). Populations: (w [1/m3], p [kg], b [kg]) per row (QMOM,
    CQMOM: the quadrature nodes; EQMOM: its kernels' secondary nodes; Laguerre ROM: its
    reconstruction's weighted points, ``signed``: negative weights kept). ``kernels``: n
    (None: the row's distinct size nodes less one, one at least, fitted to M00 .. M(2n)0:
    QMOM's and CQMOM's M(2N-1)0 not used); ``floor`` [kg]: the granules' smallest mass (0:
    [0, inf)). One node: a delta; with a floor, so is a row of relative variance at most
    DELTA_REL_VAR, and a row whose mean mass is not above the floor takes [0, inf) (named). A
    row the n kernels cannot invert takes one kernel on M00, M10, M20; a row not realizable
    even so a delta at its mean; both are named in ``notes``, as are a closest-sigma fit and
    a row with a node not finite (drawn empty). The binder fraction per size class is
    interpolated in ln p between the nodes' binder values (``reconstruct.node_binder``).
    Rows of at most two distinct nodes are fitted all at once (``_closed_form_rows``), the
    others row by row (``_fit_rows``)."""
    from ..methods.quadrature import gamma_inversion as I
    from .reconstruct import node_binder, padded_rows
    w_all, p_all = (padded_rows(populations, k) for k in range(2))
    rows = w_all.shape[0]
    floors = np.full(rows, float(floor))
    sigma, x, w = np.zeros(rows), np.zeros((rows, 1)), np.zeros((rows, 1))
    status, count = np.full(rows, I.DISCRETE), np.zeros(rows, dtype=int)
    flags = {"one": np.zeros(rows, bool), "delta": np.zeros(rows, bool),
             "bad": np.zeros(rows, bool), "below": np.zeros(rows, bool)}
    done = np.zeros(rows, bool)
    if kernels is None and not signed:
        done = _closed_form_rows(w_all, p_all, float(floor), sigma, x[:, 0], w[:, 0], status,
                                 count, flags)
    slow = _fit_rows(np.flatnonzero(~done), w_all, p_all, floors, kernels, signed, flags)
    width = max([1 if np.any(count[done] > 0) else 0] + [c.size for _, c, _, _ in slow.values()])
    cx, cw = np.zeros((rows, width)), np.zeros((rows, width))
    cx[:, :1], cw[:, :1] = x[:, :width], w[:, :width]
    for r, (sr, c, wr, st) in slow.items():
        sigma[r], status[r] = sr, st
        cx[r], cw[r] = 0.0, 0.0
        cx[r, :c.size], cw[r, :c.size] = c, wr
    mix = NodeMixture.of_arrays(sigma, cx, cw, np.zeros((rows, width)), status, rho, bivariate,
                                I.STATUS_TEXT, reported=(I.CLOSEST,), labels=labels,
                                floor=floors)
    for key, text in (("one", ONE_KERNEL_FALLBACK), ("delta", DELTA_FALLBACK),
                      ("bad", NOT_FINITE), ("below", BELOW_FLOOR)):
        if np.any(flags[key]):
            mix.notes.append(f"size distribution: {text} at "
                             f"{_rows_text(np.flatnonzero(flags[key]), labels)}")
    mix.node_binder = node_binder(populations, distinct=True) if bivariate else None
    return mix


def _closed_form_rows(w, p, floor, sigma, x, wk, status, count, flags):
    """Fills, for the rows (nodes w [1/m3], p [kg], (rows, n)) whose fit needs no inversion,
    sigma [kg], the one kernel's centre x [kg] above ``floor`` and weight wk [1/m3], status
    and kernel count, and the rows' ``flags``; returns which rows it filled. Those rows: two
    distinct valid nodes (``_two_node_fits``), a node not finite (no kernel), at most one
    valid node (a delta there, or none), and with a floor a row of no spread (a delta at the
    mean mass); every other row is left to ``_fit_rows``."""
    from ..methods.quadrature import gamma_inversion as I
    done = np.zeros(w.shape[0], bool)
    two = _two_node_fits(w, p - floor)
    if two is not None:
        ok, s2, mean2, m02, st2, delta2 = two
        if floor > 0:                   # a row of no spread is a delta (below)
            ok &= ~_no_spread(w, p)
        sigma[ok], x[ok], wk[ok], status[ok], count[ok] = s2[ok], mean2[ok], m02[ok], st2[ok], 1
        flags["delta"] |= ok & delta2
        done |= ok
    finite = np.all(np.isfinite(w), axis=1) & np.all(np.isfinite(p), axis=1)
    bad = ~done & ~finite
    status[bad], count[bad] = I.FAILED, 0
    flags["bad"] |= bad
    done |= bad
    valid = (w > 0) & (p > 0) & finite[:, None]
    ps = np.sort(np.where(valid, p, np.inf), axis=1)
    distinct = ~np.any((ps[:, 1:] == ps[:, :-1]) & np.isfinite(ps[:, 1:]), axis=1)
    nv = valid.sum(axis=1)
    wv = np.where(valid, w, 0.0)
    m0 = wv.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(valid, wv * p, 0.0).sum(axis=1) / np.where(m0 > 0, m0, 1.0)
        var = np.where(valid, wv * (p - mean[:, None]) ** 2, 0.0).sum(axis=1) / np.where(
            m0 > 0, m0, 1.0)
    open_ = ~done & finite & distinct
    single = open_ & (nv <= 1)
    node = np.where(valid, p, 0.0).sum(axis=1)      # the one valid node's mass
    sigma[single], x[single], wk[single] = 0.0, node[single] - floor, m0[single]
    status[single], count[single] = I.DISCRETE, nv[single]
    done |= single
    if floor > 0:
        flat = open_ & (nv > 1) & (m0 > 0) & (var <= DELTA_REL_VAR * mean * mean)
        sigma[flat], x[flat], wk[flat] = 0.0, mean[flat] - floor, m0[flat]
        status[flat], count[flat] = I.DISCRETE, 1
        done |= flat
    x[count == 0], wk[count == 0] = 0.0, 0.0         # no kernel: nothing in its slot
    return done


def _fit_rows(rows, w_all, p_all, floors, kernels, signed, flags):
    """The fit of each of ``rows`` (of the padded nodes w_all [1/m3], p_all [kg]) that
    ``_closed_form_rows`` did not take: {row: (sigma [kg], centres [kg] above the row's floor,
    weights [1/m3], status)}; sets the row's ``flags`` and, below the floor, floors[row] = 0."""
    from ..methods.quadrature import gamma_inversion as I
    out = {}
    nodes = _size_nodes(w_all, p_all, rows, signed)
    for r in rows.tolist():
        if not (np.all(np.isfinite(w_all[r])) and np.all(np.isfinite(p_all[r]))):
            out[r] = (0.0, np.zeros(0), np.zeros(0), I.FAILED)
            flags["bad"][r] = True
            continue
        x, w = nodes[r]
        m0 = w.sum()
        mean = (w * x).sum() / m0 if m0 > 0 else 0.0
        if floors[r] > 0 and x.size > 1 and m0 > 0:
            if (w * (x - mean) ** 2).sum() / m0 <= DELTA_REL_VAR * mean * mean:
                x, w = np.array([mean]), np.array([m0])
            elif not mean > floors[r]:
                floors[r] = 0.0
                flags["below"][r] = True
        if x.size <= 1 or not m0 > 0:
            out[r] = (0.0, x - floors[r], w, I.DISCRETE)
            continue
        n = x.size - 1 if kernels is None else int(kernels)
        sigma, c, cw, status = _fit_row(x - floors[r], w, n)
        if status == I.FAILED and n > 1:
            sigma, c, cw, status = _fit_row(x - floors[r], w, 1)
            flags["one"][r] = True
        if status == I.FAILED:
            sigma, c, cw, status = 0.0, np.array([mean - floors[r]]), np.array([m0]), I.DISCRETE
            flags["delta"][r] = True
        out[r] = (sigma, c, cw, status)
    return out


def _no_spread(w, p):
    """Per row of nodes (w [1/m3], p [kg], (rows, n)) whether its relative variance var /
    mean^2 is at most DELTA_REL_VAR (a monodisperse row)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        m0 = w.sum(axis=1)
        mean = (w * p).sum(axis=1) / m0
        var = (w * (p - mean[:, None]) ** 2).sum(axis=1) / m0
        return var <= DELTA_REL_VAR * mean * mean


def _two_node_fits(w, p):
    """Per row of two distinct valid nodes (w [1/m3], p [kg], each (rows, 2)) the one-gamma
    EQMOM ``_fit_row`` gives, in closed form: u_2 = M20 M00 / M10^2, sigma = (u_2 - 1) mean
    (the root of J, where the kernel's second moment 1 + sigma meets u_2); discrete
    (sigma = 0) where |J(0)| = (u_2 - 1) / u_2 <= the inversion's ROOT_TOLERANCE; a delta at
    the mean (flagged) where u_2 < 1. Arrays per row (ok, sigma [kg], mean [kg], m0 [1/m3],
    status, delta), ok False for a row that takes the general fit; None for populations of
    other than two nodes."""
    from ..methods.quadrature import gamma_inversion as I
    if w.shape[1] != 2:
        return None
    ok = (np.all(np.isfinite(w) & np.isfinite(p) & (w > 0) & (p > 0), axis=1)
          & (p[:, 0] != p[:, 1]))
    m0 = np.where(ok, w[:, 0] + w[:, 1], 1.0)
    mean = np.where(ok, (w[:, 0] * p[:, 0] + w[:, 1] * p[:, 1]) / m0, 1.0)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        u2 = (w[:, 0] * (p[:, 0] / mean) ** 2 + w[:, 1] * (p[:, 1] / mean) ** 2) / m0
        ok &= np.isfinite(u2) & np.isfinite(mean)
        f0 = (u2 - 1.0) / u2
    delta = ok & (f0 < 0.0)
    discrete = ok & ~delta & (np.abs(f0) <= I.ROOT_TOLERANCE)
    sigma = np.where(ok & ~delta & ~discrete, (u2 - 1.0) * mean, 0.0)
    status = np.where(delta | discrete, I.DISCRETE, I.FIT)
    return ok, sigma, mean, m0, status, delta


class NodeMixture(KernelMixture):
    """A KernelMixture fitted to quadrature nodes (``of_nodes``): its binder fraction per
    class comes from the nodes (``node_binder``: (node masses [kg], fractions [-]) per row, or
    None for a univariate scene)."""

    node_binder = None

    def class_binder(self, d_lo, d_hi):
        """Binder fraction [-] at each class's geometric centre, interpolated in ln p between
        the nodes (constant beyond the outer nodes)."""
        from .reconstruct import interpolate_rows
        if self.node_binder is None:
            return None
        centre = np.sqrt(np.asarray(d_lo, float) * np.asarray(d_hi, float))
        x, y = self.node_binder
        return interpolate_rows(np.log(mass_of_diameter(centre, self.rho)), x, y)
