"""EQMOM's own continuous size distribution: per row a mixture of gamma kernels in granule
mass p (``methods.eqmom``; docs/physics.md, section "EQMOM").

Row r holds kernels a of centre x_a [kg], number weight w_a [1/m3], binder fraction y_a [-] and
one width sigma [kg]; kernel a's number density is gamma of shape l_a = x_a / sigma and scale
sigma, its mass density p n_a(p) gamma of shape l_a + 1 (times w_a x_a), so

    Q3(d) = sum_a w_a x_a P(l_a + 1, p(d) / sigma) / sum_a w_a x_a,

P the regularised lower incomplete gamma function. sigma = 0 (a discrete fit) makes every
kernel a step at its centre. The binder fraction of a size class is the kernels' y_a weighted by
their mass in the class (exact for the per-kernel binder model). Percentiles: a row of one
kernel in closed form (the inverse of P, or its centre for sigma = 0); a row of several by
bisection between its kernels' own percentiles (the mixture's Q3 is a mean of theirs, so its
percentile lies between the lowest and the highest of them).
A row whose inversion fell back is named in ``notes`` with the fallback.
"""
from __future__ import annotations

import numpy as np

from .quantiles import bisect_quantiles, check_fractions
from .reconstruct import _rows_text, diameter_of_mass, mass_of_diameter


class KernelMixture:
    """Rows of gamma-kernel mixtures: ``kernels`` a list per row of (sigma [kg], x [kg],
    w [1/m3], y [-], status); ``rho`` the granule density [kg/m3]; ``status_text`` the
    inversion branches' names; ``reported`` the branch codes worth a note, ``failed`` the
    code of a row without kernels."""

    def __init__(self, kernels, rho, bivariate, status_text, reported=(), failed=None,
                 labels=str):
        self.rho = float(rho)
        self.rows = len(kernels)
        n = max((len(k[1]) for k in kernels), default=0)
        self.sigma = np.array([float(k[0]) for k in kernels])
        self.x = np.zeros((self.rows, n))
        self.w = np.zeros((self.rows, n))
        self.y = np.zeros((self.rows, n))
        for r, (_, x, w, y, _) in enumerate(kernels):
            self.x[r, :len(x)], self.w[r, :len(x)], self.y[r, :len(x)] = x, w, y
        self.bivariate = bivariate
        self.kernel_mass = np.where(self.w > 0, self.w * self.x, 0.0)
        self.mass = self.kernel_mass.sum(axis=1)
        self.empty = ~(self.mass > 0)
        self.notes = []
        status = np.array([int(k[4]) for k in kernels])
        for code in reported:
            rows = np.flatnonzero(status == code)
            if rows.size:
                self.notes.append(f"size distribution: EQMOM inversion {status_text[code]} at "
                                  f"{_rows_text(rows, labels)}"
                                  + ("; no granules drawn, d10/d50/d90 = 0 there"
                                     if code == failed else ""))

    def _kernel_cdf(self, p, rows=slice(None)):
        """Per row (of ``rows``) and kernel the mass fraction of the kernel below p [kg]
        (rows, n, k)."""
        from scipy.special import gammainc
        p = np.asarray(p, dtype=float)
        sigma, x = self.sigma[rows], self.x[rows]
        smooth = (sigma > 0)[:, None, None]
        sig = np.where(sigma > 0, sigma, 1.0)[:, None, None]
        shape = np.where(x > 0, x, 1.0)[:, :, None] / sig + 1.0
        with np.errstate(invalid="ignore", over="ignore"):
            g = gammainc(shape, p[:, None, :] / sig)
        step = (p[:, None, :] >= x[:, :, None]) * 1.0
        return np.where(smooth, g, step)

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
        """Per row, kernel and fraction the kernel's own percentile [kg] of granule mass
        (rows, n, len(fractions)): P^-1(l_a + 1, f) sigma, the centre where sigma = 0; NaN
        for a kernel without mass."""
        from scipy.special import gammaincinv
        f = check_fractions(fractions)
        sig = np.where(self.sigma > 0, self.sigma, 1.0)[:, None, None]
        shape = np.where(self.x > 0, self.x, 1.0)[:, :, None] / sig + 1.0
        p = gammaincinv(shape, f[None, None, :]) * sig
        p = np.where((self.sigma > 0)[:, None, None], p, self.x[:, :, None])
        return np.where((self.kernel_mass > 0)[:, :, None], p, np.nan)

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
        kq = self.kernel_quantiles(f)[full]                    # (full rows, n, k)
        with np.errstate(invalid="ignore"):
            lo, hi = np.nanmin(kq, axis=1), np.nanmax(kq, axis=1)
        q[full] = diameter_of_mass(lo, self.rho)
        several = np.flatnonzero(full)[np.any(hi > lo, axis=1)]
        if several.size:
            # a relative 1e-9 outside the kernels' own: a step at the top is reached
            sub = np.isin(np.flatnonzero(full), several)
            d_lo = diameter_of_mass(lo[sub], self.rho) * (1 - 1e-9)
            d_hi = diameter_of_mass(hi[sub], self.rho) * (1 + 1e-9)
            q[several] = bisect_quantiles(lambda d: self.cdf(d, several), f, several.size,
                                          lo=d_lo, hi=d_hi)
        return q

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


def of_states(states, aux, arrays, rho, bivariate, labels=str) -> KernelMixture:
    """The KernelMixture of EQMOM's scaled states (rows: times or cells); rows whose
    inversion took the closest-sigma fallback or failed are named (a failed row has no
    kernels: no granules to draw, d10/d50/d90 = 0 there)."""
    from ..methods.eqmom import entry
    from ..methods.quadrature import gamma_inversion as inversion
    kernels = [entry.kernels_si(s, aux, arrays) for s in np.atleast_2d(states)]
    return KernelMixture(kernels, rho, bivariate, inversion.STATUS_TEXT,
                         reported=(inversion.CLOSEST, inversion.FAILED),
                         failed=inversion.FAILED, labels=labels)


#: the branch names of ``of_nodes`` rows (after the EQMOM inversion's own)
ONE_KERNEL_FALLBACK = "not invertible with n - 1 kernels: one gamma kernel on M00, M10, M20"
DELTA_FALLBACK = "not realizable (M20 < M10^2/M00): a delta at the mean mass"
NOT_FINITE = "a node not finite: no granules drawn, d10/d50/d90 = 0 there"


def _size_nodes(w, p):
    """(masses [kg], number weights [1/m3]) of one row's distinct size nodes (CQMOM's binder
    nodes of one size node merged), nodes with w <= 0 or p <= 0 left out."""
    ok = (w > 0) & (p > 0)
    masses, inverse = np.unique(p[ok], return_inverse=True)
    return masses, np.bincount(inverse, weights=w[ok], minlength=masses.size)


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


def of_nodes(populations, rho, bivariate, labels=str) -> KernelMixture:
    """QMOM and CQMOM: per row the gamma EQMOM of n - 1 kernels (n the row's distinct size
    nodes, one kernel at least) fitted to the size moments M00 .. M(2n-2)0 the nodes carry
    exactly (docs/physics.md section 11.1; M(2n-1)0 is not used). Populations: (w [1/m3],
    p [kg], b [kg]) per row. One node: a delta. A row the n - 1 kernels cannot invert takes
    one kernel on M00, M10, M20; a row not realizable even so a delta at its mean; both are
    named in ``notes``, as are a closest-sigma fit and a row with a node not finite (drawn
    empty). The binder fraction per size class is
    interpolated in ln p between the nodes' binder fractions (``reconstruct.node_binder``)."""
    from ..methods.quadrature import gamma_inversion as I
    from .reconstruct import node_binder, padded_rows
    w_all, p_all = (padded_rows(populations, k) for k in range(2))
    kernels, one, delta, bad = [], [], [], []
    two = _two_node_fits(w_all, p_all)
    for r in range(w_all.shape[0]):
        if two is not None and two[r] is not None:
            kernels.append(two[r][:5])
            if two[r][5]:
                delta.append(r)
            continue
        if not (np.all(np.isfinite(w_all[r])) and np.all(np.isfinite(p_all[r]))):
            kernels.append((0.0, np.zeros(0), np.zeros(0), np.zeros(0), I.FAILED))
            bad.append(r)
            continue
        x, w = _size_nodes(w_all[r], p_all[r])
        if x.size <= 1:
            kernels.append((0.0, x, w, np.zeros(x.size), I.DISCRETE))
            continue
        sigma, c, cw, status = _fit_row(x, w, x.size - 1)
        if status == I.FAILED and x.size > 2:
            sigma, c, cw, status = _fit_row(x, w, 1)
            one.append(r)
        if status == I.FAILED:
            mean = (w * x).sum() / w.sum()
            sigma, c, cw, status = 0.0, np.array([mean]), np.array([w.sum()]), I.DISCRETE
            delta.append(r)
        kernels.append((sigma, c, cw, np.zeros(c.size), status))
    mix = NodeMixture(kernels, rho, bivariate, I.STATUS_TEXT, reported=(I.CLOSEST,),
                      labels=labels)
    for rows, text in ((one, ONE_KERNEL_FALLBACK), (delta, DELTA_FALLBACK), (bad, NOT_FINITE)):
        if rows:
            mix.notes.append(f"size distribution: {text} at "
                             f"{_rows_text(np.array(rows), labels)}")
    mix.node_binder = node_binder(populations) if bivariate else None
    return mix


def _two_node_fits(w, p):
    """Per row of two distinct valid nodes (w [1/m3], p [kg], each (rows, 2)) the one-gamma
    EQMOM ``_fit_row`` gives, in closed form: u_2 = M20 M00 / M10^2, sigma = (u_2 - 1) mean
    (the root of J, where the kernel's second moment 1 + sigma meets u_2); discrete
    (sigma = 0) where |J(0)| = (u_2 - 1) / u_2 <= the inversion's ROOT_TOLERANCE; a delta at
    the mean (flagged) where u_2 < 1. Entries (sigma, centres, weights, binder, status,
    delta) or None for a row that takes the general fit; None for populations of other
    than two nodes."""
    from ..methods.quadrature import gamma_inversion as I
    if w.shape[1] != 2:
        return None
    ok = (np.all(np.isfinite(w) & np.isfinite(p) & (w > 0) & (p > 0), axis=1)
          & (p[:, 0] != p[:, 1]))
    m0 = np.where(ok, w[:, 0] + w[:, 1], 1.0)
    mean = np.where(ok, (w[:, 0] * p[:, 0] + w[:, 1] * p[:, 1]) / m0, 1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        u2 = (w[:, 0] * (p[:, 0] / mean) ** 2 + w[:, 1] * (p[:, 1] / mean) ** 2) / m0
    ok &= np.isfinite(u2) & np.isfinite(mean)
    out = [None] * w.shape[0]
    for r in np.flatnonzero(ok):
        f0 = (u2[r] - 1.0) / u2[r]
        if f0 < 0.0:
            entry = (0.0, mean[r:r + 1], m0[r:r + 1], np.zeros(1), I.DISCRETE, True)
        elif abs(f0) <= I.ROOT_TOLERANCE:
            entry = (0.0, mean[r:r + 1], m0[r:r + 1], np.zeros(1), I.DISCRETE, False)
        else:
            entry = ((u2[r] - 1.0) * mean[r], mean[r:r + 1], m0[r:r + 1], np.zeros(1),
                     I.FIT, False)
        out[r] = entry
    return out


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
