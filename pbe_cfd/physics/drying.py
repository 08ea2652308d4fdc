"""Drying: evaporation of the liquid binder b from granules (docs/physics.md section 15).

A particle (p, b) [kg] loses liquid at the rate e(p, b) [kg/s], so both its mass and its
liquid drift, dp/dt = db/dt = -e; its dry mass p - b (primary solids and dissolved binder
solids) never changes. Two periods (the characteristic drying curve, van Meel 1958):

* constant rate (moisture X = b / (p - b) at or above the critical X_cr): the wet surface
  evaporates as a free liquid surface at the wet-bulb temperature, limited by the gas side,
      e_c = pi d^2 k_c rho_g (Y_s(T_wb) - Y),   k_c = Sh D_v / d,
      Sh = 2 + 0.6 Re^(1/2) Sc^(1/3)  (Ranz and Marshall 1952),  Re = rho_g u_slip d / mu_g,
  d the particle's exchange diameter (below);
* falling rate (X < X_cr): e = e_c (X - X_eq) / (X_cr - X_eq), first order in the liquid, zero
  at the equilibrium moisture X_eq (0 by default), so a granule's liquid decays exponentially
  and never crosses zero (dry granules stay dry).

Exchange diameter: the larger of the solid skeleton's, (6 (p - b) / (pi rho_s))^(1/3), and the
liquid sphere's, (6 b / (pi rho_l))^(1/3): a granule's liquid fills its pores and films its
surface (its size is the skeleton's, constant while it dries), a droplet of solution is a
liquid sphere shrinking by the d^2 law until its solids remain.

The gas a particle dries in is a tuple ``gas`` = (slip velocity [m/s], K = D_v rho_g (Y_s(T_wb)
- Y) [kg/(m s)], rho_g / mu_g [s/m2], Sc [-]) (slots GAS_SLIP, GAS_K, GAS_RE, GAS_SC). The
scene's is packed once into params (``gas_state``, plain Python); where the CFD gives the slip
velocity or the gas temperature per cell, the cell rows carry them (``gas_state_cells``,
vectorised, once at setup) and ``cell_gas`` picks each cell's. ``drying_rate`` is the
per-particle rate the methods call (numba).
"""
import math

import numba as nb
import numpy as np

from . import parameters as P

#: gas constant [J/(mol K)] and molar masses of dry air and water [kg/mol] (CODATA; IUPAC)
GAS_CONSTANT = 8.314462618
MOLAR_MASS_AIR = 0.0289647
MOLAR_MASS_WATER = 0.01801528
#: ratio of the molar masses, 0.622 in psychrometry
EPSILON = MOLAR_MASS_WATER / MOLAR_MASS_AIR
ATMOSPHERE = 101325.0
#: slots of the ``gas`` tuple (module docstring)
GAS_SLIP, GAS_K, GAS_RE, GAS_SC = 0, 1, 2, 3


def saturation_pressure(temperature):
    """Saturation pressure of water [Pa] at temperature [K]: Magnus form of Alduchov and
    Eskridge (1996), e_s = 610.94 exp(17.625 t / (t + 243.04)), t in deg C (0.4% over -40..50
    deg C)."""
    t = temperature - 273.15
    return 610.94 * math.exp(17.625 * t / (t + 243.04))


def saturation_humidity(temperature, pressure):
    """Humidity of saturated air [kg water / kg dry air] at temperature [K], pressure [Pa]."""
    ps = saturation_pressure(temperature)
    return EPSILON * ps / (pressure - ps)


def latent_heat(temperature):
    """Latent heat of evaporation of water [J/kg] at temperature [K]: 2.5008e6 - 2360 t, t in
    deg C (Rogers and Yau 1989, the first two terms of their cubic fit; 0.2% over 0..50 deg C)."""
    return 2.5008e6 - 2360.0 * (temperature - 273.15)


def humid_heat(humidity):
    """Humid heat of moist air [J/(kg dry air K)]: 1005 + 1884 Y (Perry's, psychrometry)."""
    return 1005.0 + 1884.0 * humidity


def wet_bulb_temperature(temperature, humidity, pressure):
    """Wet-bulb temperature [K] of air at temperature [K], humidity [kg/kg dry air] and pressure
    [Pa]: the root of the psychrometric balance with the Lewis relation (h = k_y c_s, air-water),
    lambda(T_wb) (Y_s(T_wb) - Y) = c_s(Y) (T - T_wb), by bisection between the dew point side
    (200 K) and T."""
    if humidity >= saturation_humidity(temperature, pressure):
        return float(temperature)
    lo, hi = 200.0, float(temperature)
    cs = humid_heat(humidity)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        gap = (latent_heat(mid) * (saturation_humidity(mid, pressure) - humidity)
               - cs * (temperature - mid))
        if gap > 0.0:
            hi = mid
        else:
            lo = mid
        if hi - lo < 1e-10:
            break
    return 0.5 * (lo + hi)


def air_density(temperature, pressure):
    """Density of dry air [kg/m3] at temperature [K] and pressure [Pa] (ideal gas)."""
    return pressure * MOLAR_MASS_AIR / (GAS_CONSTANT * temperature)


def air_viscosity(temperature):
    """Dynamic viscosity of air [Pa s]: Sutherland's law, mu0 = 1.716e-5 Pa s at 273.15 K,
    S = 110.4 K (White, Viscous Fluid Flow, 3rd ed., table 1-2)."""
    return 1.716e-5 * (temperature / 273.15) ** 1.5 * (273.15 + 110.4) / (temperature + 110.4)


def vapour_diffusivity(temperature, pressure):
    """Diffusivity of water vapour in air [m2/s]: Marrero and Mason (1972),
    D = 1.87e-10 T^2.072 / (p / 1 atm) for 280 K < T < 450 K."""
    return 1.87e-10 * temperature ** 2.072 / (pressure / ATMOSPHERE)


def gas_state(temperature, humidity, pressure):
    """(rho_g [kg/m3], mu_g [Pa s], D_v [m2/s], T_wb [K], driving force Y_s(T_wb) - Y [kg/kg])
    of the fluidising air at temperature [K], humidity [kg water / kg dry air], pressure [Pa].
    Properties are taken at the air temperature (the film at T_wb differs by a few %)."""
    t_wb = wet_bulb_temperature(temperature, humidity, pressure)
    return (air_density(temperature, pressure), air_viscosity(temperature),
            vapour_diffusivity(temperature, pressure), t_wb,
            max(saturation_humidity(t_wb, pressure) - humidity, 0.0))


def gas_state_cells(temperature, humidity, pressure):
    """(K = D_v rho_g (Y_s(T_wb) - Y) [kg/(m s)], rho_g / mu_g [s/m2], Sc [-]) per cell of air
    at the cells' temperature [K] (array), one humidity [kg water / kg dry air] and pressure
    [Pa]: ``gas_state`` vectorised, the wet bulb by the same bisection run on every cell at
    once to 1e-10 K."""
    unit, driving, reynolds, schmidt = gas_parts_cells(temperature, humidity, pressure)
    return unit * driving, reynolds, schmidt


def gas_parts_cells(temperature, humidity, pressure):
    """(D_v rho_g [kg/(m s)], Y_s(T_wb) - Y [kg/kg], rho_g / mu_g [s/m2], Sc [-]) per cell of
    air at the cells' temperature [K] (array), one humidity [kg/kg dry air] and pressure [Pa]:
    ``gas_state_cells`` with the driving force's two factors apart (the bed's air balance
    lowers the second per cell)."""
    t = np.asarray(temperature, dtype=float)
    ps = _magnus(t)
    y_s = EPSILON * ps / (pressure - ps)
    lo, hi = np.full(t.shape, 200.0), t.copy()
    cs = humid_heat(humidity)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        pm = _magnus(mid)
        gap = latent_heat(mid) * (EPSILON * pm / (pressure - pm) - humidity) - cs * (t - mid)
        hi = np.where(gap > 0.0, mid, hi)
        lo = np.where(gap > 0.0, lo, mid)
        if np.all(hi - lo < 1e-10):
            break
    t_wb = np.where(humidity >= y_s, t, 0.5 * (lo + hi))
    pw = _magnus(t_wb)
    driving = np.maximum(EPSILON * pw / (pressure - pw) - humidity, 0.0)
    rho = air_density(t, pressure)
    mu = air_viscosity(t)
    diffusivity = vapour_diffusivity(t, pressure)
    return diffusivity * rho, driving, rho / mu, mu / (rho * diffusivity)


def _magnus(temperature):
    """``saturation_pressure`` [Pa] of an array of temperatures [K]."""
    t = temperature - 273.15
    return 610.94 * np.exp(17.625 * t / (t + 243.04))


@nb.njit(cache=True, inline="always")
def scene_gas(params):
    """The ``gas`` tuple (module docstring) of the scene's air: params' DRY_SLIP [m/s],
    DRY_DRIVING [kg/(m s)], DRY_RE [s/m2], DRY_SCHMIDT [-]."""
    return (params[P.DRY_SLIP], params[P.DRY_DRIVING], params[P.DRY_RE],
            params[P.DRY_SCHMIDT])


@nb.njit(cache=True, inline="always")
def cell_gas(cell, params, config):
    """The ``gas`` tuple of one cell: its row's SLIP_VELOCITY [m/s] where config
    DRYING_CELL_SLIP is 1, its GAS_DRIVING, GAS_REYNOLDS, GAS_SCHMIDT where DRYING_CELL_AIR
    is 1, the scene's (``scene_gas``) otherwise."""
    slip = cell[P.SLIP_VELOCITY] if config[P.DRYING_CELL_SLIP] == 1 else params[P.DRY_SLIP]
    if config[P.DRYING_CELL_AIR] == 1:
        return (slip, cell[P.GAS_DRIVING], cell[P.GAS_REYNOLDS], cell[P.GAS_SCHMIDT])
    return (slip, params[P.DRY_DRIVING], params[P.DRY_RE], params[P.DRY_SCHMIDT])


@nb.njit(cache=True, inline="always")
def sherwood(reynolds, schmidt):
    """Ranz-Marshall Sherwood number 2 + 0.6 Re^(1/2) Sc^(1/3) [-] (Ranz and Marshall 1952)."""
    return 2.0 + 0.6 * math.sqrt(reynolds) * schmidt ** (1.0 / 3.0)


@nb.njit(cache=True)
def exchange_diameter(p, b, params):
    """Exchange diameter [m] of a particle of mass p [kg] holding liquid b [kg]: the larger of
    its solid skeleton's and its liquid sphere's (module docstring)."""
    dry = max(p - b, 0.0)
    skeleton = (6.0 * dry / (math.pi * params[P.DENSITY])) ** (1.0 / 3.0)
    liquid = (6.0 * max(b, 0.0) / (math.pi * params[P.BINDER_DENSITY])) ** (1.0 / 3.0)
    return max(skeleton, liquid)


@nb.njit(cache=True, inline="always")
def surface_rate(d, gas):
    """Constant-period evaporation rate [kg/s] of a wet sphere of diameter d [m] in ``gas``
    (module docstring): pi d Sh D_v rho_g (Y_s(T_wb) - Y)."""
    return math.pi * d * sherwood(gas[GAS_RE] * gas[GAS_SLIP] * d, gas[GAS_SC]) * \
        gas[GAS_K]


@nb.njit(cache=True)
def drying_rate(p, b, gas, params):
    """Evaporation rate e [kg/s] of the liquid b [kg] of a particle of mass p [kg] in ``gas``
    (module docstring: slip velocity [m/s], K = D_v rho_g (Y_s - Y) [kg/(m s)], rho_g / mu_g
    [s/m2], Sc [-]): the constant rate e_c = pi d Sh K times the falling-rate factor
    min(1, (X - X_eq) / (X_cr - X_eq)), X = b / (p - b); 0 for b <= 0 or X <= X_eq. Slots of
    params: DRY_CRITICAL X_cr, DRY_EQUILIBRIUM X_eq [-], the densities."""
    if b <= 0.0:
        return 0.0
    rate = surface_rate(exchange_diameter(p, b, params), gas)
    dry = p - b
    x_cr = params[P.DRY_CRITICAL]
    x_eq = params[P.DRY_EQUILIBRIUM]
    if dry > 0.0 and b < x_cr * dry:
        factor = (b / dry - x_eq) / (x_cr - x_eq)
        if factor <= 0.0:
            return 0.0
        rate *= factor
    return rate


#: sub-step of the liquid-sphere period of ``advance_liquid``: this share of b / e
LIQUID_SPHERE_STEP = 0.02


@nb.njit(cache=True)
def advance_liquid(p, b, dt, gas, params):
    """Liquid [kg] of a particle of mass p [kg] holding liquid b [kg] after drying for dt [s]
    in ``gas`` (module docstring; its dry mass p - b fixed). While the liquid sphere is the larger
    exchange diameter the rate follows b: exactly (``liquid_sphere_after``, to the diameter
    switch b = (rho_l / rho_s) m_s) where X_cr <= rho_l / rho_s; else (the falling rate
    already in the sphere) classical RK4 steps of LIQUID_SPHERE_STEP b / e. Once the skeleton
    is the larger, e_c is constant and the drying curve is solved exactly: b - e_c t down to
    X_cr m_s, then X_eq m_s + (b - X_eq m_s) exp(-e_c t / ((X_cr - X_eq) m_s)), so the liquid
    never falls below X_eq m_s >= 0. A pure liquid (p = b) is a sphere to the end, exactly 0
    (``liquid_sphere_after``)."""
    dry = p - b
    if b <= 0.0 or dt <= 0.0:
        return b
    if not dry > 0.0:
        return liquid_sphere_after(b, dt, gas, params, 0.0)
    ratio = params[P.BINDER_DENSITY] / params[P.DENSITY]
    left = dt
    if b > ratio * dry and params[P.DRY_CRITICAL] <= ratio:   # the sphere, exactly
        b_sw = ratio * dry
        t_sw = liquid_sphere_time(b, b_sw, gas, params)
        if left < t_sw:
            return liquid_sphere_after(b, left, gas, params, b_sw)
        left -= t_sw
        b = b_sw
    while left > 0.0 and b > ratio * dry:        # the liquid sphere: d shrinks with b
        e1 = drying_rate(dry + b, b, gas, params)
        if not e1 > 0.0:
            return b
        h = min(left, LIQUID_SPHERE_STEP * b / e1)
        b2 = max(b - 0.5 * h * e1, 0.0)
        e2 = drying_rate(dry + b2, b2, gas, params)
        b3 = max(b - 0.5 * h * e2, 0.0)
        e3 = drying_rate(dry + b3, b3, gas, params)
        b4 = max(b - h * e3, 0.0)
        e4 = drying_rate(dry + b4, b4, gas, params)
        b = max(b - h * (e1 + 2.0 * e2 + 2.0 * e3 + e4) / 6.0, 0.0)
        left -= h
    if not left > 0.0:
        return b
    e_c = surface_rate((6.0 * dry / (math.pi * params[P.DENSITY])) ** (1.0 / 3.0), gas)
    b_c = params[P.DRY_CRITICAL] * dry
    b_eq = params[P.DRY_EQUILIBRIUM] * dry
    if b > b_c:
        t_lin = (b - b_c) / e_c
        if left <= t_lin:
            return b - e_c * left
        left -= t_lin
        b = b_c
    if b <= b_eq:
        return b
    tau = (params[P.DRY_CRITICAL] - params[P.DRY_EQUILIBRIUM]) * dry / e_c
    return b_eq + (b - b_eq) * math.exp(-left / tau)


@nb.njit(cache=True, inline="always")
def _sphere_integral(u, c):
    """G(u) = int_0^u s^3 / (2 + c s) ds [m^2] (u = d^(1/2) [m^(1/2)], c [m^(-1/2)]): the
    series u^4 sum_n (-c u / 2)^n / (2 (n + 4)) below c u = 1/2 (no cancellation), else the
    closed form (x^3/3 - x^2 + 4 x - 8 ln(1 + x/2)) / c^4, x = c u."""
    x = c * u
    if x < 0.5:
        total = 0.0
        term = 1.0
        for n in range(60):
            total += term / (2.0 * (n + 4))
            term *= -0.5 * x
            if abs(term) < 1e-18:
                break
        return u ** 4 * total
    return (x ** 3 / 3.0 - x * x + 4.0 * x - 8.0 * math.log1p(0.5 * x)) / c ** 4


@nb.njit(cache=True, inline="always")
def _sphere_g(b, c, rho_l):
    """G(u) of ``_sphere_integral`` for a liquid sphere of mass b [kg], density rho_l."""
    if not b > 0.0:
        return 0.0
    return _sphere_integral((6.0 * b / (math.pi * rho_l)) ** (1.0 / 6.0), c)


@nb.njit(cache=True, inline="always")
def _sphere_c(gas):
    """c = 0.6 (rho_g slip / mu_g)^(1/2) Sc^(1/3) [m^(-1/2)] of ``gas``: Sh = 2 + c d^(1/2)."""
    return 0.6 * math.sqrt(gas[GAS_RE] * gas[GAS_SLIP]) * gas[GAS_SC] ** (1.0 / 3.0)


@nb.njit(cache=True)
def liquid_sphere_time(b, b_end, gas, params):
    """Time [s] a liquid sphere of mass b [kg] takes to evaporate down to b_end [kg] (0 <=
    b_end <= b) in ``gas`` (module docstring): rho_l (G(u) - G(u_end)) / K
    (``liquid_sphere_after``)."""
    c = _sphere_c(gas)
    rho_l = params[P.BINDER_DENSITY]
    return rho_l * (_sphere_g(b, c, rho_l) - _sphere_g(b_end, c, rho_l)) / gas[GAS_K]


@nb.njit(cache=True)
def liquid_sphere_after(b, dt, gas, params, b_end):
    """Mass [kg] of a liquid sphere of mass b [kg] after evaporating for dt [s] in ``gas``
    (module docstring), not below b_end [kg] (docs/physics.md section 15, "A liquid sphere,
    exactly"). With b = rho_l pi d^3 / 6 and e = pi d Sh K (K = D_v rho_g (Y_s - Y),
    Sh = 2 + c d^(1/2), c = 0.6 (rho_g slip / mu_g)^(1/2) Sc^(1/3)), u = d^(1/2) obeys
    G(u(t)) = G(u0) - K t / rho_l, G(u) = int_0^u s^3 / (2 + c s) ds (the d^2 law d^2 = d0^2 -
    8 K t / rho_l at c = 0). Returns exactly b_end once G(u0) - K dt / rho_l <= G(u_end) +
    1e-14 G(u0) (for b_end = 0: the droplet is gone; the margin is the round-off of that
    difference), else the root u of G(u) = target (Newton from u0: G convex and increasing, so
    the iterates fall monotonically onto the root)."""
    if b <= 0.0 or dt <= 0.0:
        return max(b, 0.0)
    rho_l = params[P.BINDER_DENSITY]
    c = _sphere_c(gas)
    u = (6.0 * b / (math.pi * rho_l)) ** (1.0 / 6.0)
    g0 = _sphere_integral(u, c)
    target = g0 - gas[GAS_K] * dt / rho_l
    if not target > _sphere_g(b_end, c, rho_l) + 1e-14 * g0:
        return b_end
    for _ in range(100):
        step = (_sphere_integral(u, c) - target) * (2.0 + c * u) / u ** 3
        u_new = u - step
        if not u_new > 0.0:
            u_new = 0.5 * u
        if abs(u_new - u) <= 1e-15 * u:
            u = u_new
            break
        u = u_new
    d = u * u
    return max(rho_l * math.pi * d * d * d / 6.0, b_end)
