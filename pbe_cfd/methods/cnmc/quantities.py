"""What the cNMC box (``cnmc.box``) reports at an output time: its moments, droplet number,
mean diameters and binder fraction (``box_quantities``), and its granules' mass per class of a
size lattice with their exact mass percentiles (``box_size_classes``). All quantities SI."""
import math

import numba as nb
import numpy as np

from .slots import C_D as _C_D

MOMENT_NAMES = ("M00", "M10", "M01", "M20", "M11", "M02")
QUANTITY_NAMES = MOMENT_NAMES + ("droplet_number_density", "d32_m", "d43_m", "binder_fraction")
N_QUANTITIES = len(QUANTITY_NAMES)

#: the size-class lattice of the box's mass histogram: edges d_k = 10^(LO + k / PER_DECADE) m,
#: k = 0 .. PSD_BINS (0.1 um to 1 m); a granule outside it is counted in the end class
PSD_LOG10_LO = -7.0
PSD_PER_DECADE = 50
PSD_BINS = 7 * PSD_PER_DECADE
#: the mass fractions of the box's exact percentiles (d10, d50, d90)
PSD_FRACTIONS = (0.1, 0.5, 0.9)


@nb.njit(cache=True)
def box_size_classes(p, b, isdrop, rho, classes, percentiles):
    """The granules' (isdrop 0) mass and binder mass [kg] per class of the size lattice
    (PSD_LOG10_LO, PSD_PER_DECADE; ``classes`` (PSD_BINS, 2), overwritten) and their exact
    mass-based percentiles [m] at PSD_FRACTIONS (``percentiles``, 3): the diameter of the
    first granule, in order of mass, at which the cumulative mass reaches the fraction.
    p, b [kg]; rho the particle density [kg/m3]. No granule: percentiles 0."""
    classes[:, :] = 0.0
    n_bins = classes.shape[0]
    total = 0.0
    for k in range(p.size):
        if isdrop[k] != 0:
            continue
        d = (_C_D * p[k] / rho) ** (1.0 / 3.0)
        j = int(math.floor((math.log10(d) - PSD_LOG10_LO) * PSD_PER_DECADE))
        j = min(max(j, 0), n_bins - 1)
        classes[j, 0] += p[k]
        classes[j, 1] += b[k]
        total += p[k]
    percentiles[:] = 0.0
    if total <= 0.0:
        return
    order = np.argsort(p)
    acc = 0.0
    q = 0
    for i in range(order.size):
        k = order[i]
        if isdrop[k] != 0:
            continue
        acc += p[k]
        while q < 3 and acc >= PSD_FRACTIONS[q] * total:
            percentiles[q] = (_C_D * p[k] / rho) ** (1.0 / 3.0)
            q += 1
        if q == 3:
            break


@nb.njit(cache=True)
def box_quantities(p, b, isdrop, conc, rho, row):
    """Fill ``row`` (length N_QUANTITIES, order QUANTITY_NAMES) from the box.

    p, b [kg]; isdrop 1 for a free droplet; conc the box's mass concentration M10 [kg/m3],
    which sets the volume V = sum p / conc [m3]; rho the particle density [kg/m3].
    Moments are SI per m3 of the whole population (free droplets included).
    """
    n = p.size
    sp = 0.0
    sb = 0.0
    spp = 0.0
    spb = 0.0
    sbb = 0.0
    s2 = 0.0
    s3 = 0.0
    s4 = 0.0
    nd = 0
    for k in range(n):
        pk = p[k]
        bk = b[k]
        sp += pk
        sb += bk
        spp += pk * pk
        spb += pk * bk
        sbb += bk * bk
        d = (_C_D * pk / rho) ** (1.0 / 3.0)
        d2 = d * d
        s2 += d2
        s3 += d2 * d
        s4 += d2 * d2
        if isdrop[k] != 0:
            nd += 1
    vol = sp / conc
    row[0] = n / vol
    row[1] = sp / vol
    row[2] = sb / vol
    row[3] = spp / vol
    row[4] = spb / vol
    row[5] = sbb / vol
    row[6] = nd / vol
    row[7] = s3 / s2
    row[8] = s4 / s3
    row[9] = sb / sp


@nb.njit(cache=True, inline="always")
def store_output(k_out, box, conc, out, classes, percentiles, evaporated, dry):
    """Store the box as output row ``k_out`` (``box_quantities`` at the mass concentration
    ``conc`` [kg/m3], ``box_size_classes``, the evaporated liquid dry[0] [kg/m3])."""
    box_quantities(box.p, box.b, box.isdrop, conc, box.rho, out[k_out])
    box_size_classes(box.p, box.b, box.isdrop, box.rho, classes[k_out], percentiles[k_out])
    evaporated[k_out] = dry[0]
