"""SI output columns from a population given as weighted particles (docs/physics.md section 11).

Every method can describe its population as weights w [1/m3] at masses p [kg] and binder b
[kg] (QMOM: its nodes; cNMC: its particles; Laguerre ROM: its reconstruction on a grid), plus free
droplets. Moments a method carries exactly are taken from its state instead; the rest, and the
mean diameters, come from that description.
"""
from __future__ import annotations

import math
import re

import numpy as np

STANDARD_BIVARIATE = ("M00", "M10", "M01", "M20", "M11", "M02")
STANDARD_UNIVARIATE = ("M00", "M10", "M20")
DERIVED = ("d32_m", "d43_m", "binder_fraction")


def moment_columns(carried, bivariate):
    """Output moment names: the standard set first, then other carried moments (i, then j)."""
    standard = STANDARD_BIVARIATE if bivariate else STANDARD_UNIVARIATE
    extra = sorted((n for n in carried if n.startswith("M") and n not in standard),
                   key=lambda n: (int(n[2]), int(n[1])))
    return list(standard) + extra


def diameter(p, density):
    """Volume-equivalent diameter [m] of mass p [kg] at density [kg/m3]."""
    return np.cbrt(6.0 * np.asarray(p, dtype=float) / (math.pi * density))


def mean_diameters(weights, p, density):
    """(d32, d43) [m] of weights [1/m3] at masses p [kg]; zeros for an empty population."""
    w = np.asarray(weights, dtype=float)
    d = diameter(p, density)
    m2 = np.sum(w * d ** 2)
    m3 = np.sum(w * d ** 3)
    m4 = np.sum(w * d ** 4)
    d32 = m3 / m2 if m2 > 0 else 0.0
    d43 = m4 / m3 if m3 > 0 else 0.0
    return float(d32), float(d43)


def mean_diameters_rows(weights, p, density):
    """``mean_diameters`` of every row of (rows, particles) weights [1/m3] and masses p [kg]:
    arrays (d32, d43) [m], zeros for an empty row; the same arithmetic row by row."""
    w = np.asarray(weights, dtype=float)
    d = diameter(p, density)
    m2 = np.sum(w * d ** 2, axis=1)
    m3 = np.sum(w * d ** 3, axis=1)
    m4 = np.sum(w * d ** 4, axis=1)
    d32 = np.where(m2 > 0, m3 / np.where(m2 > 0, m2, 1.0), 0.0)
    d43 = np.where(m3 > 0, m4 / np.where(m3 > 0, m3, 1.0), 0.0)
    return d32, d43


def moment_orders(name):
    """(i, j) of a moment named "M<i><j>" (M_ij [kg^(i+j)/m3]): j the last digit (binder
    orders stay below 10), i the digits before it (mass orders reach 10: EQMOM with five
    kernels carries "M100")."""
    return int(name[1:-1]), int(name[-1])


def is_moment_name(name):
    """True for a moment name "M<i><j>" (see ``moment_orders``)."""
    return re.fullmatch(r"M[0-9]{2,3}", name) is not None

def columns_from_particle_rows(weights, p, b, names):
    """``columns_from_particles`` of every row of (rows, particles) arrays: name -> (rows,)
    moments M_ij [kg^(i+j)/m3], the same arithmetic row by row."""
    w = np.asarray(weights, dtype=float)
    p = np.asarray(p, dtype=float)
    b = np.asarray(b, dtype=float)
    orders = [moment_orders(name) for name in names]
    return {name: np.sum(w * p ** i * b ** j, axis=1) for name, (i, j) in zip(names, orders)}


def columns_from_particles(weights, p, b, names):
    """Moments M_ij [kg^(i+j)/m3] named in ``names`` from weighted particles."""
    w = np.asarray(weights, dtype=float)
    p = np.asarray(p, dtype=float)
    b = np.asarray(b, dtype=float)
    out = {}
    for name in names:
        i, j = moment_orders(name)
        out[name] = float(np.sum(w * p ** i * b ** j))
    return out
