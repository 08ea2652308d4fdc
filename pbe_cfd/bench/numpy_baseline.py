"""The QMOM right-hand side as plain NumPy/SciPy: the baseline of the throughput study."""
from __future__ import annotations

import math

import numpy as np

from ..physics import parameters as P
from ..physics.kernels import CONSTANT, EKE, KTGF, PRODUCT, SUM


# ============================================================================ NumPy/SciPy baseline
class NumpyQMOM:
    """The QMOM right-hand side as a user would write it without this package: NumPy Wheeler
    recurrence, ``numpy.linalg.eigh`` of the Jacobi matrix, binder per node by
    ``numpy.linalg.solve`` of the weighted Vandermonde system (clipped to [0, p]), the kernel
    and efficiency formulas of DESIGN section 3 as plain Python functions, Python loops over
    pairs and moments. Same state layout and scaling as ``methods.qmom`` (scaled moments), so
    ``scipy.integrate.solve_ivp(baseline.rhs, ...)`` integrates exactly what the package does
    (without its realizability control)."""

    def __init__(self, params, config):
        self.p = [float(x) for x in params]
        self.n = int(config[P.ORDER])
        self.kernel = int(config[P.KERNEL])
        self.geometric = int(config[P.USE_GEOMETRIC]) == 1
        self.physical = int(config[P.USE_PHYSICAL]) == 1
        self.saturation = int(config[P.USE_SATURATION]) == 1
        self.separate = int(config[P.SEPARATE_DROPLETS]) == 1
        self.bivariate = int(config[P.BIVARIATE]) == 1
        self.n_state = int(config[P.N_STATE])

    # -- quadrature
    def quadrature(self, m):
        n = self.n
        m0 = m[0]
        if not m0 > 0:
            return np.zeros(0), np.zeros(0)
        mean = m[1] / m0
        mu = np.array([m[k] / (m0 * mean ** k) for k in range(2 * n)])
        sigma = np.zeros((n + 1, 2 * n + 1))
        sigma[1, :2 * n] = mu
        a = np.zeros(n)
        b = np.zeros(n)
        a[0] = mu[1] / mu[0]
        n_eff = 1
        for k in range(1, n):
            for l in range(k, 2 * n - k):
                sigma[k + 1, l] = (sigma[k, l + 1] - a[k - 1] * sigma[k, l]
                                   - b[k - 1] * sigma[k - 1, l])
            if not sigma[k + 1, k] > 1e-11 * abs(sigma[k, k + 1]):
                break
            a[k] = sigma[k + 1, k + 1] / sigma[k + 1, k] - sigma[k, k] / sigma[k, k - 1]
            b[k] = sigma[k + 1, k] / sigma[k, k - 1]
            n_eff = k + 1
        off = np.sqrt(b[1:n_eff])
        jacobi = np.diag(a[:n_eff]) + np.diag(off, 1) + np.diag(off, -1)
        vals, vecs = np.linalg.eigh(jacobi)
        return vals * mean, vecs[0, :] ** 2 * m0

    def binder(self, m, x, w):
        n = len(x)
        if not self.bivariate or n == 0:
            return np.zeros(n)
        rhs = np.asarray(m[2 * self.n:2 * self.n + n])
        vander = np.vander(x, n, increasing=True).T * w
        try:
            b = np.linalg.solve(vander, rhs)
        except np.linalg.LinAlgError:
            b = np.full(n, rhs[0] / max(np.sum(w * x), 1e-300)) * x
        return np.clip(b, 0.0, x)

    # -- physics of DESIGN section 3, one pair at a time
    def props(self, pm, bm):
        p = self.p
        d = (6.0 * pm / (math.pi * p[P.DENSITY])) ** (1.0 / 3.0)
        y = bm / pm if pm > 0 else 0.0
        x = pm / (p[P.REFERENCE_VOLUME] * p[P.DENSITY]) if p[P.REFERENCE_VOLUME] > 0 else 0.0
        eta = 1.0 / (1.0 + math.exp(-p[P.GEO_SLOPE] * (y - p[P.GEO_CENTRE])))
        layer = math.exp(p[P.PHI_SLOPE] * (y - p[P.PHI_CENTRE]) / 3.0)
        return pm, bm, d, x, eta, layer

    def cell_factor(self, alpha, theta, d43):
        p = self.p
        if self.kernel != KTGF:
            return p[P.RATE]
        cap = p[P.ALPHA_MIN_FRICTION]
        if cap > 0 and alpha > cap:
            alpha = cap
        g0 = 1.0 if alpha <= 0 else 1.0 / (1.0 - (alpha / p[P.ALPHA_MAX]) ** (1.0 / 3.0))
        return p[P.RATE] * g0 * math.sqrt(max(theta, 0.0)) * d43 ** 1.5

    def rate(self, r1, r2, factor, u0):
        p = self.p
        p1, b1, d1, x1, eta1, l1 = r1
        p2, b2, d2, x2, eta2, l2 = r2
        k = self.kernel
        if k == CONSTANT:
            beta = factor
        elif k == SUM:
            beta = factor * (p1 + p2)
        elif k == PRODUCT:
            beta = factor * p1 * p2
        elif k == EKE:
            beta = factor * (x1 ** (1 / 3) + x2 ** (1 / 3)) ** 2 * math.sqrt(1 / x1 + 1 / x2)
        elif k == KTGF:
            beta = factor * (d1 + d2) ** 2 * math.sqrt(1 / d1 ** 3 + 1 / d2 ** 3)
        else:
            raise ValueError(f"the NumPy baseline has no kernel of code {k}")
        psi = 1.0
        if self.geometric:
            psi *= 1.0 - (1.0 - eta1) * (1.0 - eta2)
        if self.physical:
            st = (4 * p[P.DENSITY] * u0 * d1 * d2 * (d1 + d2) ** 2
                  / (9 * p[P.BINDER_VISCOSITY] * (d1 ** 3 + d2 ** 3)))
            ratio = p[P.GYRATION_RADIUS] * (l1 + l2) / p[P.ASPERITY]
            st_crit = 2.0 * math.log(ratio) if ratio > 1.0 else 0.0
            w = p[P.STOKES_WIDTH]
            if w <= 0 or st_crit <= 0:
                psi *= 1.0 if st <= st_crit else 0.0
            else:
                psi *= 0.5 * (1.0 - math.tanh((st - st_crit) / (w * st_crit)))
        if self.saturation:
            binder = b1 + b2
            solid = p1 + p2 - binder
            if solid > 0:
                eps = p[P.POROSITY]
                s = binder / solid * p[P.DENSITY] * (1 - eps) / (p[P.BINDER_DENSITY] * eps)
                psi *= min(1.0, s / p[P.SATURATION_MAX])
        return beta * psi

    def rhs(self, _t, y, cell):
        """d(state)/dt (scaled moments per s) of one cell (alpha, Theta, u0, injection)."""
        p = self.p
        n_max = self.n
        out = np.zeros(self.n_state)
        x, w = self.quadrature(y)
        b = self.binder(y, x, w)
        ns, ms = p[P.NUMBER_SCALE], p[P.MASS_SCALE]
        rows = [self.props(x[a] * ms, b[a] * ms) for a in range(len(x))]
        d43 = 0.0
        if self.kernel == KTGF and len(x):
            d = np.array([r[2] for r in rows])
            d43 = float(np.sum(w * d ** 4) / np.sum(w * d ** 3))
        factor = self.cell_factor(cell[P.ALPHA], cell[P.THETA], d43)
        u0 = cell[P.COLLISION_VELOCITY]
        for a in range(len(x)):
            for c in range(a, len(x)):
                pair = w[a] * w[c] * ns * self.rate(rows[a], rows[c], factor, u0)
                if a == c:
                    pair *= 0.5
                s = x[a] + x[c]
                out[0] -= pair
                for k in range(2, 2 * n_max):
                    out[k] += pair * (s ** k - x[a] ** k - x[c] ** k)
                if self.bivariate:
                    for k in range(1, n_max):
                        out[2 * n_max + k] += pair * (b[a] * (s ** k - x[a] ** k)
                                                      + b[c] * (s ** k - x[c] ** k))
        inj = cell[P.INJECTION] / ns
        pd = p[P.DROPLET_MASS]
        xd = pd / ms
        if self.separate:
            nd = y[-1]
            if nd > 0:
                drop = self.props(pd, pd)
                for a in range(len(x)):
                    flux = nd * w[a] * ns * p[P.DROPLET_FACTOR] * self.rate(rows[a], drop,
                                                                            factor, u0)
                    s = x[a] + xd
                    for k in range(1, 2 * n_max):
                        out[k] += flux * (s ** k - x[a] ** k)
                    if self.bivariate:
                        for k in range(n_max):
                            out[2 * n_max + k] += flux * (s ** k * (b[a] + xd) - x[a] ** k * b[a])
                    out[-1] -= flux
            out[-1] += inj
        elif inj:
            for k in range(2 * n_max):
                out[k] += inj * xd ** k
                if self.bivariate and k < n_max:
                    out[2 * n_max + k] += inj * xd ** (k + 1)
        return out
