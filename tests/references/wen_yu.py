"""Reference minimum fluidisation velocity: Wen & Yu (1966) as they derived it, the Ergun
equation at incipient fluidisation with their two groups 1/(phi eps^3) = 14 and
(1 - eps)/(phi^2 eps^3) = 11:

    1.75 * 14 Re^2 + 150 * 11 Re = Ar,   Re = rho_g U_mf d / mu,
    Ar = rho_g (rho_s - rho_g) g d^3 / mu^2,

solved here as a quadratic by numpy's polynomial roots (not by the closed form the package
uses). The package's form rounds 1650 / (2 x 24.5) = 33.67 to 33.7 and 1/24.5 = 0.040816 to
0.0408: at the viscous end Re -> 0.0408 Ar / (2 x 33.7) against Ar / 1650, 1.19e-3 lower
(1 - 1650 x 0.0408 / 67.4); at the inertial end sqrt(0.0408 Ar) against sqrt(Ar / 24.5),
2e-4 lower. Between the two the difference lies between these bounds."""
import numpy as np

G = 9.81


def u_mf(d, rho_s, rho_g, mu):
    """U_mf [m/s] of particles of diameter d [m], density rho_s [kg/m3] in a gas of density
    rho_g [kg/m3] and viscosity mu [Pa s]."""
    ar = rho_g * (rho_s - rho_g) * G * d ** 3 / mu ** 2
    roots = np.roots([1.75 * 14.0, 150.0 * 11.0, -ar])
    re = float(max(r.real for r in roots if abs(r.imag) < 1e-12))
    return re * mu / (rho_g * d)
