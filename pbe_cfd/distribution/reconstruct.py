"""One size distribution per method, reconstructed from what the method carries.

Every reconstruction holds rows (output times or cells) of the granules' mass-based
distribution (free droplets of a separate droplet population excluded) and offers

* ``mass``: the granule mass per row [kg/m3] (the weight of a row in a bed mixture);
* ``cdf(d)``: the mass fraction Q3 below diameter d [m], d of shape (k,) or (rows, k);
* ``quantiles(fractions)``: the diameters [m] at mass fractions (rows, len(fractions)), 0 for
  a row without granules;
* ``class_binder(d_lo, d_hi)``: the granules' mean binder fraction b/p (binder mass over
  granule mass) in each class [d_lo, d_hi] (rows, k), or None for a univariate scene;
* ``notes``: one line per failure (the rows named, the fallback stated).

The reconstructions and their derivations: docs/physics.md section 11.1.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics import parameters as P
from .quantiles import bisect_quantiles, check_fractions, interpolated_cdf

#: relative variance var/mean^2 below which a row is a delta at its mean (monodisperse)
DELTA_REL_VAR = 1.0e-10
#: Laguerre density: size classes per decade of diameter, decades below d(p_max), and
#: Gauss-Legendre points per class (in ln p) and in the binder fraction y = b/p
LAGUERRE_PER_DECADE, LAGUERRE_DECADES, LAGUERRE_GAUSS_P, LAGUERRE_GAUSS_Y = 150, 2, 2, 12
#: bisections of a bed mixture's percentile inside the rows' own range: 2^-20 of it
MIXTURE_BISECTIONS = 20
#: gamma fit: Q3 closer than this to 0 or 1 is taken as 0 or 1 (no gamma function evaluated)
TAIL = 1.0e-14
#: Laguerre density: negative mass share (of the positive mass) above which a row is named
NEGATIVE_SHARE_NOTE = 1.0e-3


def diameter_of_mass(p, rho):
    """Volume-equivalent diameter [m] of granule mass p [kg] at density rho [kg/m3]."""
    return np.cbrt(6.0 * np.asarray(p, dtype=float) / (math.pi * rho))


def mass_of_diameter(d, rho):
    """Granule mass [kg] of diameter d [m] at density rho [kg/m3]."""
    return math.pi / 6.0 * rho * np.asarray(d, dtype=float) ** 3


def _rows_text(rows, labels) -> str:
    names = [labels(int(r)) for r in rows[:3]]
    more = f" and {len(rows) - 3} more" if len(rows) > 3 else ""
    return ", ".join(names) + more


class GammaFit:
    """QMOM and CQMOM: per row the gamma density in granule mass p with the row's granule
    moments M00, M10, M20 [1/m3, kg/m3, kg2/m3] (EQMOM with one gamma kernel; see
    docs/physics.md section 11.1): n(p) = M00 p^(k-1) e^(-p/theta) / (Gamma(k) theta^k), k =
    mean^2/var, theta = var/mean. Its mass density p n(p) is the gamma density of shape k + 1,
    so Q3(d) = P(k + 1, p(d)/theta) and the percentiles are closed-form. A row with var <=
    DELTA_REL_VAR mean^2 is a delta at its mean; an unrealizable row (var < 0 beyond
    round-off, or a non-finite moment) falls back to a delta at its mean and is named in
    ``notes``. ``binder``: (nodes p [kg], binder fraction y [-]) arrays (rows, n) from
    ``node_binder``, interpolated in ln p between the nodes (constant beyond them), or
    None."""

    def __init__(self, m0, m1, m2, rho, binder=None, labels=str):
        m0, m1, m2 = (np.asarray(v, dtype=float) for v in (m0, m1, m2))
        self.rho = float(rho)
        self.rows = m0.size
        finite = np.isfinite(m0) & np.isfinite(m1) & np.isfinite(m2)
        self.empty = finite & ~((m0 > 0) & (m1 > 0))
        ok = finite & ~self.empty
        mean = np.where(ok, m1 / np.where(ok, m0, 1.0), 0.0)
        rel = np.where(ok, m2 * np.where(ok, m0, 1.0) / np.where(ok, m1, 1.0) ** 2 - 1.0, 0.0)
        bad = ~finite | (ok & (rel < -1.0e-9))
        self.delta = bad | (rel <= DELTA_REL_VAR)
        self.mean = np.where(bad, np.where(np.isfinite(mean), mean, 0.0), mean)
        self.shape = np.where(self.delta, 1.0, 1.0 / np.where(self.delta, 1.0, rel))
        self.theta = np.where(self.delta, 1.0, self.mean * rel)
        self.mass = np.where(ok, m1, 0.0)
        self.binder = binder
        self._tails = None
        self.notes = []
        if np.any(bad):
            rows = np.flatnonzero(bad)
            self.notes.append(f"size distribution: unrealizable moments (M20 < M10^2/M00 or not "
                              f"finite) at {_rows_text(rows, labels)}; a delta at the mean "
                              "mass is used there")
            self.mass = np.where(bad & np.isfinite(m1) & (m1 > 0), m1, self.mass)
            self.empty = self.empty | ~(self.mass > 0)

    def _support(self):
        """Per row the masses [kg] below and above which Q3 is within TAIL of 0 and 1 (the
        gamma function is evaluated only between them)."""
        if self._tails is None:
            from scipy.special import gammaincinv
            a = self.shape + 1.0
            self._tails = (gammaincinv(a, TAIL) * self.theta,
                           gammaincinv(a, 1.0 - TAIL) * self.theta)
        return self._tails

    def cdf(self, d):
        """Q3 [-] at diameters d [m] ((k,) or (rows, k)) per row (0 in an empty row)."""
        from scipy.special import gammainc
        p = mass_of_diameter(np.broadcast_to(d, (self.rows,) + np.shape(d)[-1:]), self.rho)
        lo, hi = self._support()
        smooth = ~(self.delta | self.empty)[:, None]
        out = np.where(smooth, (p >= hi[:, None]) * 1.0, (p >= self.mean[:, None]) * 1.0)
        inside = smooth & (p > lo[:, None]) & (p < hi[:, None])
        a = np.broadcast_to((self.shape + 1.0)[:, None], p.shape)
        x = p / self.theta[:, None]
        out[inside] = gammainc(a[inside], x[inside])
        return np.where(self.empty[:, None], 0.0, out)

    def quantiles(self, fractions):
        """Diameters [m] at the mass fractions per row, closed-form (0 in an empty row)."""
        from scipy.special import gammaincinv
        f = check_fractions(fractions)
        p = gammaincinv((self.shape + 1.0)[:, None], f[None, :]) * self.theta[:, None]
        p = np.where(self.delta[:, None], self.mean[:, None], p)
        return np.where(self.empty[:, None], 0.0, diameter_of_mass(p, self.rho))

    def class_binder(self, d_lo, d_hi):
        """Binder fraction [-] at each class's geometric centre, from the nodes."""
        if self.binder is None:
            return None
        centre = np.sqrt(np.asarray(d_lo, float) * np.asarray(d_hi, float))
        x, y = self.binder
        return interpolate_rows(np.log(mass_of_diameter(centre, self.rho)), x, y)


def interpolate_rows(q, x, y):
    """Per row, y interpolated linearly in ln x at q = ln p (k,), constant beyond the row's
    outer valid nodes: x (rows, n) node masses [kg] sorted per row, invalid nodes +inf at
    the end; y (rows, n). A row without a valid node gives 0."""
    valid = np.isfinite(x)
    nv = valid.sum(axis=1)
    lx = np.where(valid, np.log(np.where(valid, x, 1.0)), np.inf)
    j = _count_at_or_below(lx, np.asarray(q, dtype=float))           # (rows, k)
    last = np.maximum(nv - 1, 0)[:, None]
    j0 = np.clip(j - 1, 0, last)
    j1 = np.clip(j, 0, last)
    x0, x1 = np.take_along_axis(lx, j0, 1), np.take_along_axis(lx, j1, 1)
    y0, y1 = np.take_along_axis(y, j0, 1), np.take_along_axis(y, j1, 1)
    with np.errstate(invalid="ignore"):       # inf - inf in rows without a node (masked below)
        gap = np.where(j1 > j0, x1 - x0, 1.0)
        t = np.where(j1 > j0, (q[None, :] - x0) / gap, 0.0)
    return np.where((nv > 0)[:, None], y0 + t * (y1 - y0), 0.0)


def _count_at_or_below(lx, q):
    """Per row of lx (rows, n) the number of its entries <= each q (k,): (rows, k) counts,
    by bisection in the row sorted (the count does not depend on the entries' order)."""
    out = np.empty((lx.shape[0], q.size), dtype=np.intp)
    ordered = np.all(lx[:, 1:] >= lx[:, :-1], axis=1)
    for r in range(lx.shape[0]):
        row = lx[r] if ordered[r] else np.sort(lx[r])
        out[r] = np.searchsorted(row, q, side="right")
    out[:, np.isnan(q)] = 0             # no entry is <= NaN (searchsorted puts NaN last)
    return out


def stacked_rows(populations, k):
    """Entry k (0: w, 1: p, 2: b) of every row's population as one (rows, n) array in one
    conversion where every row has n nodes, else None."""
    try:
        out = np.array([r[k] for r in populations], dtype=float)
    except ValueError:         # rows of different lengths
        return None
    return out if out.ndim == 2 else None


def padded_rows(populations, k):
    """Entry k (0: w, 1: p, 2: b) of every row's population as one (rows, n_max) array,
    rows with fewer nodes (a degenerate quadrature) padded with zeros (w = 0: no node)."""
    out = stacked_rows(populations, k)
    if out is not None:
        return out
    parts = [np.asarray(r[k], dtype=float).ravel() for r in populations]
    out = np.zeros((len(parts), max((x.size for x in parts), default=0)))
    for r, x in enumerate(parts):
        out[r, :x.size] = x
    return out


def node_binder(populations, distinct=False):
    """(node masses x [kg], mass-mean binder fraction y [-]) of quadrature populations (w
    [1/m3], p [kg], b [kg]) per row, each (rows, n) (n the most nodes of a row) sorted by x
    per row (nodes with w <= 0 or p <= 0: x = +inf at the end, y = 0 there). Nodes sharing
    one mass (CQMOM's binder nodes of one size node) share the mass-mean binder fraction of
    their group (``node_groups.binder_of_groups``). ``distinct``: each mass once, n the most
    masses of a row (at least 1 where a row has nodes): what ``interpolate_rows`` reads of
    the nodes, the same interpolation."""
    from .node_groups import binder_of_groups
    rows = [[np.asarray(r[k], dtype=float).ravel() for r in populations] for k in range(3)]
    sizes = np.array([a.size for a in rows[1]], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    w, p, b = (np.concatenate(a) if a else np.zeros(0) for a in rows)
    n = int(sizes.max(initial=0))
    x, y = np.empty((len(sizes), n)), np.empty((len(sizes), n))
    widest = binder_of_groups(w, p, b, starts, distinct, x, y)
    if distinct and n > 0:
        width = max(int(widest), 1)
        return x[:, :width].copy(), y[:, :width].copy()
    return x, y


def gamma_of_populations(populations, rho, bivariate, labels=str) -> GammaFit:
    """The GammaFit of quadrature populations (w [1/m3], p [kg], b [kg]) per row: the nodes
    return the carried M00, M10, M20 (QMOM and CQMOM with two or more size nodes carry them
    exactly; one node carries M00, M10 only and gives a delta)."""
    w, p = (padded_rows(populations, k) for k in range(2))
    binder = node_binder(populations) if bivariate else None
    return GammaFit(w.sum(axis=1), (w * p).sum(axis=1), (w * p * p).sum(axis=1), rho,
                    binder=binder, labels=labels)


class ClassTable:
    """A distribution given by its granule mass (and binder mass) per class of a diameter
    lattice: ``log_edges`` (n + 1,) ln d [m]; ``mass`` (rows, n) [any unit]; ``binder``
    (rows, n) in the same unit or None. Q3 is linear in ln d inside a class (the density is
    constant per ln d there). ``exact``: optional (rows, 3) percentiles at FRACTIONS known
    better than the table (the cNMC's particle lists)."""

    def __init__(self, log_edges, mass, binder=None, total=None, exact=None, notes=()):
        self.log_edges = np.asarray(log_edges, dtype=float)
        mass = np.asarray(mass, dtype=float)
        self.rows = mass.shape[0]
        tot = mass.sum(axis=1)
        self.empty = ~(tot > 0)
        norm = np.where(self.empty, 1.0, tot)[:, None]
        self.cumulative = np.hstack([np.zeros((self.rows, 1)), np.cumsum(mass, axis=1) / norm])
        self.binder_cumulative = (None if binder is None else np.hstack(
            [np.zeros((self.rows, 1)), np.cumsum(np.asarray(binder, float), axis=1) / norm]))
        self.mass = np.where(self.empty, 0.0, tot if total is None else total)
        self.exact = exact
        self.notes = list(notes)

    def cdf(self, d):
        """Q3 [-] at diameters d [m] ((k,) or (rows, k)) per row."""
        return interpolated_cdf(self.log_edges, self.cumulative, d)

    def quantiles(self, fractions):
        """Diameters [m] at the mass fractions per row (0 in an empty row)."""
        f = check_fractions(fractions)
        if self.exact is not None and tuple(f) == _cnmc_box().PSD_FRACTIONS:
            return np.asarray(self.exact, dtype=float)
        q = bisect_quantiles(self.cdf, f, self.rows, lo=math.exp(self.log_edges[0]),
                             hi=math.exp(self.log_edges[-1]))
        return np.where(self.empty[:, None], 0.0, q)

    def class_binder(self, d_lo, d_hi):
        """Binder mass over granule mass [-] in each class (0 where the class is empty)."""
        if self.binder_cumulative is None:
            return None
        dm = self.cdf(d_hi) - self.cdf(d_lo)
        db = (interpolated_cdf(self.log_edges, self.binder_cumulative, d_hi)
              - interpolated_cdf(self.log_edges, self.binder_cumulative, d_lo))
        return np.where(dm > 0, db / np.where(dm > 0, dm, 1.0), 0.0)


def _cnmc_box():
    """The cNMC's box module (its lattice), imported by a scene that uses it only."""
    from ..methods.cnmc import box
    return box


def cnmc_lattice_edges() -> np.ndarray:
    """ln d [m] of the cNMC's size-class lattice edges (``methods.cnmc_box``)."""
    cnmc_box = _cnmc_box()
    k = np.arange(cnmc_box.PSD_BINS + 1)
    return (cnmc_box.PSD_LOG10_LO + k / cnmc_box.PSD_PER_DECADE) * math.log(10.0)


def cnmc_table(result, bivariate) -> ClassTable:
    """The cNMC ensemble's histogram (``cnmc.simulate_ensemble``'s result): the replicas'
    mean granule mass fraction per lattice class, its exact particle-list percentiles."""
    frac = np.asarray(result["psd_mass_fraction"], dtype=float)
    binder = frac * np.asarray(result["psd_binder_fraction"]) if bivariate else None
    exact = np.column_stack([result["d10_m"], result["d50_m"], result["d90_m"]])
    return ClassTable(cnmc_lattice_edges(), frac, binder, exact=exact)


def laguerre_table(states, aux, arrays, bivariate, labels=str) -> ClassTable:
    """The Laguerre ROM's own density (``methods.laguerre.reconstruct``, wet and dry
    classes) integrated per class of a diameter lattice of LAGUERRE_DECADES decades below
    d(p_max): the granule mass p^2 n d(ln p) by Gauss-Legendre in ln p, the integral over b in
    [0, min(p, b_max)] by Gauss-Legendre in b / min(p, b_max). Negative class masses (the
    expansion dips below zero) are set to 0; a row whose negative share exceeds
    NEGATIVE_SHARE_NOTE of its mass is named."""
    from ..methods.laguerre.layout import AUX_B_MAX, AUX_ORDER, AUX_P_MAX
    from ..methods.laguerre.rhs import reconstruct, reconstruct_dry
    params, config = arrays.params, arrays.config
    p_max, b_max = float(aux[AUX_P_MAX]), float(aux[AUX_B_MAX])
    m = int(aux[AUX_ORDER])
    n_cls = LAGUERRE_PER_DECADE * LAGUERRE_DECADES
    ln_p_edges = math.log(p_max) + 3.0 * math.log(10.0) * LAGUERRE_DECADES * (
        np.arange(n_cls + 1) / n_cls - 1.0)
    gp, gw = np.polynomial.legendre.leggauss(LAGUERRE_GAUSS_P)
    gy, gwy = np.polynomial.legendre.leggauss(LAGUERRE_GAUSS_Y)
    gy, gwy = 0.5 * (gy + 1.0), 0.5 * gwy
    h = np.diff(ln_p_edges)
    lnp = ln_p_edges[:-1, None] + 0.5 * h[:, None] * (gp[None, :] + 1.0)     # (n, g)
    wq = 0.5 * h[:, None] * gw[None, :]
    p = np.exp(lnp).ravel()
    top = np.minimum(p, b_max)
    b = top[:, None] * gy[None, :]
    mass = np.zeros((len(states), n_cls))
    binder = np.zeros((len(states), n_cls)) if bivariate else None
    negative = np.zeros(len(states))
    for r, state in enumerate(states):
        n_pb = reconstruct(state, aux, params, config, p[:, None], b)          # (P, Y)
        n_p = top * (n_pb @ gwy)
        if np.any(np.asarray(state[m * m:m * m + m]) != 0.0):
            n_p = n_p + reconstruct_dry(state, aux, params, p)
        cls = np.sum((p * p * n_p).reshape(lnp.shape) * wq, axis=1)
        pos = np.maximum(cls, 0.0)
        negative[r] = -np.sum(np.minimum(cls, 0.0)) / max(np.sum(pos), 1e-300)
        mass[r] = pos
        if bivariate:
            b_int = top * ((n_pb * b) @ gwy)
            b_cls = np.sum((p * b_int).reshape(lnp.shape) * wq, axis=1)
            binder[r] = np.where(cls > 0, np.clip(b_cls, 0.0, None), 0.0)
    log_edges = (ln_p_edges - math.log(math.pi / 6.0 * params[P.DENSITY])) / 3.0
    notes = []
    flagged = np.flatnonzero(negative > NEGATIVE_SHARE_NOTE)
    if flagged.size:
        worst = int(flagged[np.argmax(negative[flagged])])
        notes.append(f"size distribution: the Laguerre density is negative for "
                     f"{100 * negative[worst]:.2g}% of the mass at {labels(worst)} (and "
                     f"{flagged.size - 1} more); the negative classes are set to 0 there")
    return ClassTable(log_edges, mass, binder, notes=notes)


class Mixture:
    """One row: the mixture of a reconstruction's rows weighted by ``weights`` (the granule
    mass of each row, e.g. a cell's M10 [kg/m3] times its volume [m3]): the bed's
    distribution of a coupled run. Q3 = sum_c W_c Q3_c / sum_c W_c; percentiles by
    bisection; the binder fraction of a class the mass-weighted mean of the rows'."""

    def __init__(self, parts, weights):
        self.parts = parts
        w = np.asarray(weights, dtype=float)
        self.weights = np.where(w > 0, w, 0.0)
        self.rows = 1
        total = float(self.weights.sum())
        self.mass = np.array([total])
        self.empty = np.array([not total > 0])
        self.notes = list(parts.notes)

    def cdf(self, d):
        """Q3 [-] at diameters d [m] ((k,) or (1, k))."""
        return self._weighted_cdf(self.parts.cdf(np.asarray(d, dtype=float).reshape(-1)))

    def _weighted_cdf(self, rows):
        """Q3 (1, k) of the mixture from its rows' Q3 (rows, k) at the same diameters."""
        if self.empty[0]:
            return np.zeros((1, rows.shape[1]))
        return (self.weights @ rows)[None, :] / self.mass[0]

    def quantiles(self, fractions):
        """Diameters [m] at the mass fractions (1, len(fractions))."""
        f = check_fractions(fractions)
        if self.empty[0]:
            return np.zeros((1, f.size))
        lo, hi = self.bounds(f)
        return bisect_quantiles(self.cdf, f, 1, lo=lo, hi=hi, halvings=MIXTURE_BISECTIONS)

    def bounds(self, fractions):
        """(lowest, highest) of the weighted rows' own percentiles [m] at the fractions, each
        (1, len(fractions)): the mixture's percentile lies between them (Q3 of the mixture is
        a mean of the rows' Q3)."""
        q = np.asarray(self.parts.quantiles(fractions), dtype=float)[self.weights > 0]
        # a relative 1e-9 outside them: a step at the top is reached despite round-off in d(p)
        return q.min(axis=0)[None, :] * (1 - 1e-9), q.max(axis=0)[None, :] * (1 + 1e-9)

    def psd_rows(self, d, d_lo, d_hi, edges):
        """(``cdf(d)``, the classes' binder fraction (1, k) or None) from one evaluation of
        the rows' Q3 at d [m]: the classes [d_lo, d_hi] [m] weighted by the rows' mass
        between the diameters ``d[edges]`` (k + 1 indices: the class edges, as psd.csv's
        q3), each row's binder fraction of a class from ``parts.class_binder``."""
        d = np.asarray(d, dtype=float).reshape(-1)
        k = np.size(d_lo)
        if self.empty[0]:
            none = self.parts.class_binder(d_lo, d_hi) is None
            return np.zeros((1, d.size)), None if none else np.zeros((1, k))
        rows = self.parts.cdf(d)
        at = self._weighted_cdf(rows)
        y = self.parts.class_binder(d_lo, d_hi)
        if y is None:
            return at, None
        edge = rows[:, edges]
        dm = self.weights[:, None] * (edge[:, 1:] - edge[:, :-1])
        tot = dm.sum(axis=0)
        return at, (np.where(tot > 0, (dm * y).sum(axis=0) / np.where(tot > 0, tot, 1.0), 0.0)
                    [None, :])

    def class_binder(self, d_lo, d_hi):
        """Mass-weighted binder fraction [-] of the rows in each class (1, k)."""
        y = self.parts.class_binder(d_lo, d_hi)
        if y is None:
            return None
        dm = self.weights[:, None] * (self.parts.cdf(d_hi) - self.parts.cdf(d_lo))
        tot = dm.sum(axis=0)
        return (np.where(tot > 0, (dm * y).sum(axis=0) / np.where(tot > 0, tot, 1.0), 0.0)
                [None, :])


class Stack:
    """Rows of one-row distributions (a ``Mixture`` per output time) seen as one
    reconstruction with a row each."""

    def __init__(self, items):
        # a sequence (a list, or an ``io.spool.Spool`` read one item at a time) is kept as it is
        self.items = items if hasattr(items, "__len__") and hasattr(items, "__getitem__") \
            else list(items)
        self.rows = len(self.items)
        mass, self.notes = [], []
        for it in self.items:
            mass.append(float(it.mass[0]))
            self.notes.extend(n for n in it.notes if n not in self.notes)
        self.mass = np.array(mass)
        self.empty = ~(self.mass > 0)

    def _each(self, fn, d):
        d = np.asarray(d, dtype=float)
        return np.vstack([fn(it, d if d.ndim == 1 else d[r]) for r, it in enumerate(self.items)])

    def cdf(self, d):
        """Q3 [-] at diameters d [m] ((k,) or (rows, k)) per row."""
        return self._each(lambda it, x: it.cdf(x), d)

    def quantiles(self, fractions):
        """Diameters [m] at the mass fractions per row."""
        return np.vstack([it.quantiles(fractions) for it in self.items])

    def bounds(self, fractions):
        """Per row the (lowest, highest) percentiles of the mixtures' rows (``Mixture``)."""
        parts = [it.bounds(fractions) for it in self.items if not it.empty[0]]
        return np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])

    def class_binder(self, d_lo, d_hi):
        """Binder fraction [-] per class per row, or None."""
        parts = [it.class_binder(d_lo, d_hi) for it in self.items]
        return None if any(p is None for p in parts) else np.vstack(parts)

    def psd_rows(self, d, d_lo, d_hi, edges):
        """Per row ``Mixture.psd_rows``: (Q3 at d, class binder fractions or None), each
        mixture read once."""
        parts = [it.psd_rows(d, d_lo, d_hi, edges) for it in self.items]
        binder = [b for _, b in parts]
        return (np.vstack([a for a, _ in parts]),
                None if any(b is None for b in binder) else np.vstack(binder))
