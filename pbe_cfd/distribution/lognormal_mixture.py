"""The lognormal EQMOM's own size distribution: per row a mixture of lognormal kernels in
granule mass p (``methods.eqmom`` with ``[method] kernel = "lognormal"``; docs/physics.md,
section 16).

Row r holds kernels a of median x_a [kg], number weight w_a [1/m3], binder fraction y_a [-] and
one log-width sigma [-]. Kernel a's number density is lognormal in p (ln p normal of mean
ln x_a, standard deviation sigma); its mass density p n_a is w_a x_a e^(sigma^2/2) times the
lognormal of ln-mean ln x_a + sigma^2 (Aitchison and Brown 1957, the moment-distribution
theorem), so

    Q3(d) = sum_a w_a x_a e^(sigma^2/2) Phi(z_a) / sum_a w_a x_a e^(sigma^2/2),
    z_a = (ln p(d) - ln x_a - sigma^2) / sigma,

Phi the standard normal distribution function; its derivative in p is phi(z_a) / (sigma p).
Kernel a's own mass percentile f is x_a exp(sigma^2 + sigma Phi^-1(f)). sigma = 0 (a discrete
fit) makes every kernel a step at x_a. Percentiles, binder per class and the fallbacks' notes
as ``kernel_mixture.KernelMixture`` (its Newton search between the kernels' percentiles).
"""
from __future__ import annotations

import numpy as np

from .kernel_mixture import KernelMixture, in_row_blocks
from .quantiles import check_fractions


class LognormalMixture(KernelMixture):
    """Rows of lognormal-kernel mixtures: ``kernels`` a list per row of (sigma [-], x [kg]
    (medians), w [1/m3], y [-], status); the other arguments as ``KernelMixture`` (no
    floor)."""

    def _set(self, sigma, x, w, y, status, rho, bivariate, status_text, reported, failed,
             labels, floor):
        super()._set(sigma, x, w, y, status, rho, bivariate, status_text, reported, failed,
                     labels, None)
        # the kernel's mass per m3: w_a times its mean mass x_a e^(sigma^2/2)
        self.kernel_mass = np.where(self.w > 0,
                                    self.w * self.x * np.exp(0.5 * sigma[:, None] ** 2), 0.0)
        self.mass = self.kernel_mass.sum(axis=1)
        self.empty = ~(self.mass > 0)

    def _kernel_cdf_rows(self, p, rows, slope, floored):
        """Per row and kernel the mass fraction below p [kg] (len(rows), k): Phi(z_a) (module
        docstring), a step at x_a where sigma = 0; ``slope``: also phi(z_a) / (sigma p)
        [1/kg]."""
        from scipy.special import ndtr
        sigma, x = self.sigma[rows], self.x[rows]
        smooth = (sigma > 0)[:, None, None]
        sig = np.where(sigma > 0, sigma, 1.0)[:, None, None]
        centre = np.log(np.where(x > 0, x, 1.0))[:, :, None] + sig ** 2
        pp = p[:, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (np.log(np.maximum(pp, 0.0)) - centre) / sig
            q = np.where(smooth, ndtr(z), (pp >= x[:, :, None]) * 1.0)
            if not slope:
                return q
            dq = np.where(pp > 0, np.exp(-0.5 * z * z) / (np.sqrt(2.0 * np.pi) * sig * pp),
                          0.0)
        return q, np.where(smooth, dq, 0.0)

    def kernel_quantiles(self, fractions):
        """Per row, kernel and fraction the kernel's own mass percentile [kg] twice (lowest,
        highest; each (rows, n, len(fractions))): x_a exp(sigma^2 + sigma Phi^-1(f)), x_a
        where sigma = 0; NaN for a kernel without mass."""
        f = check_fractions(fractions)

        def rows_of(b):
            from scipy.special import ndtri
            sigma, x = self.sigma[b][:, None, None], self.x[b][:, :, None]
            q = np.where(sigma > 0, x * np.exp(sigma ** 2 + sigma * ndtri(f[None, None, :])),
                         x + 0.0 * f[None, None, :])
            q = np.where((self.kernel_mass[b] > 0)[:, :, None], q, np.nan)
            return q, q
        return in_row_blocks(rows_of, self.rows, (self.x.shape[1], f.size), 2)


def is_lognormal(aux) -> bool:
    """True if an EQMOM aux (``methods.eqmom.state.aux_array``) is of lognormal kernels."""
    from ..methods.eqmom.state import AUX_FAMILY
    from ..methods.quadrature.gamma_inversion import LOGNORMAL
    return aux is not None and len(aux) > AUX_FAMILY and int(aux[AUX_FAMILY]) == LOGNORMAL


def of_states(states, aux, arrays, rho, bivariate, labels=str) -> LognormalMixture:
    """The LognormalMixture of the lognormal EQMOM's scaled states (rows: times or cells); the
    fallbacks' rows named as ``kernel_mixture.of_states`` does."""
    from ..methods.eqmom import entry
    from ..methods.quadrature import gamma_inversion as inversion
    kernels = [entry.kernels_si(s, aux, arrays) for s in np.atleast_2d(states)]
    return LognormalMixture(kernels, rho, bivariate, inversion.STATUS_TEXT,
                            reported=(inversion.FEWER, inversion.CLOSEST, inversion.FAILED),
                            failed=inversion.FAILED, labels=labels)
