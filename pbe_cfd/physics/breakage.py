"""Breakage (docs/physics.md section 8): the selection-function and daughter-rule registries.

A granule of mass p' [kg] holding binder b' [kg] breaks at the selection rate S(p') [1/s] into
two daughters; each daughter keeps the parent's binder fraction (binder splits in proportion to
mass), so a daughter with the mass share u of its parent is (u p', u b'). Free droplets (a
population of their own) never break. The population balance gains

    dn/dt += int S(r') b(r | r') n(r') dr' - S(r) n(r),

and since every daughter of (p', b') scales both masses by the same u, the mixed moments
M_ij = int p^i b^j n gain

    dM_ij/dt = int S(p) (F(i + j) - 1) p^i b^j n,      F(k) = int_0^1 u^k beta(u) du,

beta(u) the number density of daughters with mass share u (two daughters: F(0) = 2, F(1) = 1).
``uniform`` daughters (b(p | p') = 2 / p'): beta = 2, F(k) = 2 / (k + 1); ``equal`` halves:
beta = 2 delta(u - 1/2), F(k) = 2^(1 - k). Hence the closed forms of docs/physics.md section 8.

Selection functions, like the aggregation kernels, split into a cell factor g(alpha, theta,
u0, params) [1/s] shared by every granule of a cell and a particle part f(p, g, params) [1/s]:

* ``constant``:    S = s0;
* ``power``:       S = s0 (p / p_ref)^a;
* ``collisional``: S = s0 g0(alpha) sqrt(Theta / Theta_ref) (p / p_ref)^a, g0 the radial
  distribution of the kernels (Sinclair-Jackson, capped at alpha_min_friction as the ktgf
  kernel does): the collision frequency of a granule scales as g0 sqrt(Theta). Optionally gated
  by the Stokes deformation number of Tardos, Khan and Mort (1997): St_def = rho_g u0^2 / (2 Y)
  with u0 = 4 sqrt(Theta / pi) (the collision velocity of the cell, as for aggregation), rho_g
  the granule density (the scene's particle density) and Y the granule yield strength [Pa];
  granules break only where St_def > St_def* (``critical_deformation_number``). St_def does
  not depend on the granule size, so the gate is a property of the cell (a step in Theta).

Adding a selection function or a daughter rule (see CONTRIBUTING.md): write its numba
function(s) (``inline="always"``) and add one entry to ``SELECTION_REGISTRY`` or
``DAUGHTER_REGISTRY`` with a new code. The scene accepts its name, the dispatchers below get
its branch (QMOM, Laguerre ROM and cNMC call only these), ``pbe-cfd plan`` prints it, and
``tests/physics/test_registries.py`` checks it. The cNMC bounds S over a mass interval by its value at
the interval's ends, so a selection function must be monotone in p (the registry test checks).
"""
import math
from typing import Callable, NamedTuple

import numba as nb

from . import parameters as P
from .kernels import radial_distribution
from .registry import cell_dispatch, particle_dispatch, scalar_dispatch

# ---- selection codes (config[P.BREAKAGE_SELECTION]) ----------------------------------------
CONSTANT = 0
POWER = 1
COLLISIONAL = 2

# ---- daughter-rule codes (config[P.BREAKAGE_DAUGHTERS]) ------------------------------------
UNIFORM = 0
EQUAL = 1


# ---- Stokes deformation number (Tardos, Khan and Mort 1997) ----------------------------------
@nb.njit(cache=True, inline="always")
def stokes_deformation_number(u0, params):
    """St_def = rho_g u0^2 / (2 Y) [-] of a granule colliding at u0 [m/s]: rho_g =
    params[DENSITY] [kg/m3], Y = params[YIELD_STRENGTH] [Pa] (> 0)."""
    return params[P.DENSITY] * u0 * u0 / (2.0 * params[P.YIELD_STRENGTH])


@nb.njit(cache=True, inline="always")
def deformation_gate(u0, params):
    """1 where granules colliding at u0 [m/s] break (St_def > St_def*), else 0 [-]; 1 when no
    yield strength is set (params[YIELD_STRENGTH] <= 0: the gate is off)."""
    if params[P.YIELD_STRENGTH] <= 0.0:
        return 1.0
    return 1.0 if stokes_deformation_number(u0, params) > params[P.CRITICAL_DEFORMATION] else 0.0


# ---- cell factors g(alpha [-], theta [m2/s2], u0 [m/s], params) [1/s] -------------------------
@nb.njit(cache=True, inline="always")
def breakage_rate_constant(alpha, theta, u0, params):
    """Cell factor of a selection that does not depend on the cell: s0 = params[BREAKAGE_RATE]
    [1/s]."""
    return params[P.BREAKAGE_RATE]


@nb.njit(cache=True, inline="always")
def collisional_cell_factor(alpha, theta, u0, params):
    """s0 g0(alpha) sqrt(Theta / Theta_ref) x gate [1/s]: g0 at min(alpha, alpha_min_friction)
    (as ``kernels.ktgf_cell_factor``), Theta_ref = params[BREAKAGE_REFERENCE_THETA] [m2/s2],
    the Stokes deformation gate at the cell's collision velocity u0 [m/s]."""
    if deformation_gate(u0, params) == 0.0:
        return 0.0
    cap = params[P.ALPHA_MIN_FRICTION]
    if cap > 0.0 and alpha > cap:
        alpha = cap
    g0 = radial_distribution(alpha, params[P.ALPHA_MAX])
    return (params[P.BREAKAGE_RATE] * g0
            * math.sqrt(max(theta, 0.0) / params[P.BREAKAGE_REFERENCE_THETA]))


# ---- selection functions f(p [kg], cell factor [1/s], params) -> S [1/s] ----------------------
@nb.njit(cache=True, inline="always")
def constant_selection(p, cell_factor, params):
    """S = s0 [1/s], whatever the mass."""
    return cell_factor


@nb.njit(cache=True, inline="always")
def power_selection(p, cell_factor, params):
    """S = g (p / p_ref)^a [1/s]: g the cell factor [1/s], p_ref =
    params[BREAKAGE_REFERENCE_MASS] [kg], a = params[BREAKAGE_EXPONENT] >= 0."""
    a = params[P.BREAKAGE_EXPONENT]
    if a == 0.0:
        return cell_factor
    if a == 1.0:
        return cell_factor * (p / params[P.BREAKAGE_REFERENCE_MASS])
    return cell_factor * (p / params[P.BREAKAGE_REFERENCE_MASS]) ** a


# ---- daughter rules ----------------------------------------------------------------------------
@nb.njit(cache=True, inline="always")
def uniform_daughter_moments(k):
    """F(k) = int_0^1 u^k 2 du = 2 / (k + 1) [-]: uniform binary daughters, b(p|p') = 2/p'."""
    return 2.0 / (k + 1.0)


@nb.njit(cache=True, inline="always")
def uniform_daughter_share(r):
    """Mass share of the first daughter for a uniform random number r in (0, 1): u = r (the
    second daughter takes 1 - u)."""
    return r


@nb.njit(cache=True, inline="always")
def equal_daughter_moments(k):
    """F(k) = 2 (1/2)^k = 2^(1 - k) [-]: two equal halves."""
    return 2.0 ** (1.0 - k)


@nb.njit(cache=True, inline="always")
def equal_daughter_share(r):
    """Mass share of the first daughter: 1/2, whatever r."""
    return 0.5


# ---- the registries ---------------------------------------------------------------------------
class Selection(NamedTuple):
    """One breakage selection function of the registry.

    name         the scene's ``[breakage] selection``
    code         config[P.BREAKAGE_SELECTION] (unique, >= 0)
    function     numba f(p [kg], cell_factor [1/s], params) -> S [1/s], monotone in p
    cell_factor  numba g(alpha [-], theta [m2/s2], u0 [m/s], params) -> [1/s]
    keys         the ``[breakage]`` keys it reads besides ``rate`` (the scene refuses the
                 others and requires those without a default)
    cell_fields  what the cell must provide ("solids_fraction", "granular_temperature")
    formula      how ``pbe-cfd plan`` writes it
    """
    name: str
    code: int
    function: Callable
    cell_factor: Callable = breakage_rate_constant
    keys: tuple = ()
    cell_fields: tuple = ()
    formula: str = ""


class Daughters(NamedTuple):
    """One daughter rule (binary breakage; binder in proportion to mass).

    name     the scene's ``[breakage] daughters``
    code     config[P.BREAKAGE_DAUGHTERS] (unique, >= 0)
    moments  numba F(k) = int u^k beta(u) du [-] (F(0) = 2 daughters, F(1) = 1: mass kept)
    share    numba u(r): mass share of the first daughter for a uniform r in (0, 1), so that
             u and 1 - u are distributed as beta / 2 (the Monte Carlo's split)
    formula  how ``pbe-cfd plan`` writes it
    """
    name: str
    code: int
    moments: Callable
    share: Callable
    formula: str = ""


_POWER_KEYS = ("exponent", "reference_mass")
SELECTION_REGISTRY = (
    Selection("constant", CONSTANT, constant_selection, formula="S = s0"),
    Selection("power", POWER, power_selection, keys=_POWER_KEYS,
              formula="S = s0 (p / p_ref)^a"),
    Selection("collisional", COLLISIONAL, power_selection, cell_factor=collisional_cell_factor,
              keys=_POWER_KEYS + ("reference_granular_temperature", "yield_strength",
                                  "critical_deformation_number"),
              cell_fields=("solids_fraction", "granular_temperature"),
              formula="S = s0 g0(alpha) sqrt(Theta / Theta_ref) (p / p_ref)^a"),
)

DAUGHTER_REGISTRY = (
    Daughters("uniform", UNIFORM, uniform_daughter_moments, uniform_daughter_share,
              formula="two daughters, mass share uniform on (0, 1)"),
    Daughters("equal", EQUAL, equal_daughter_moments, equal_daughter_share,
              formula="two equal halves"),
)

#: name -> registry entry
SELECTION_BY_NAME = {s.name: s for s in SELECTION_REGISTRY}
DAUGHTERS_BY_NAME = {d.name: d for d in DAUGHTER_REGISTRY}

# ---- dispatch by code (numba; one branch per entry, unknown code: NaN) -------------------------
#: S [1/s] of a granule of mass p [kg]: selection_function(code, p, cell_factor, params)
selection_function = particle_dispatch((s.code, s.function) for s in SELECTION_REGISTRY)
#: the cell factor [1/s]: selection_cell_factor(code, alpha [-], theta [m2/s2], u0 [m/s], params)
selection_cell_factor = cell_dispatch((s.code, s.cell_factor) for s in SELECTION_REGISTRY)
#: F(k) of the daughter rule: daughter_moment_factor(code, k)
daughter_moment_factor = scalar_dispatch((d.code, d.moments) for d in DAUGHTER_REGISTRY)
#: mass share of the first daughter: daughter_share(code, r), r uniform in (0, 1)
daughter_share = scalar_dispatch((d.code, d.share) for d in DAUGHTER_REGISTRY)


@nb.njit(cache=True)
def cell_selection_factor(cell, params, config):
    """The selection's cell factor [1/s] for a cell row (ALPHA [-], THETA [m2/s2],
    COLLISION_VELOCITY [m/s], ...); 0 without breakage (config[BREAKAGE] == 0)."""
    if config[P.BREAKAGE] != 1:
        return 0.0
    return selection_cell_factor(config[P.BREAKAGE_SELECTION], cell[P.ALPHA], cell[P.THETA],
                                 cell[P.COLLISION_VELOCITY], params)


@nb.njit(cache=True)
def selection_rate(p, alpha, theta, u0, params, config):
    """Breakage rate S [1/s] of one granule of mass p [kg] in a cell with alpha [-], theta
    [m2/s2] and collision velocity u0 [m/s]: the single-particle form of the registry (0
    without breakage, NaN for an unknown code)."""
    if config[P.BREAKAGE] != 1:
        return 0.0
    code = config[P.BREAKAGE_SELECTION]
    factor = selection_cell_factor(code, alpha, theta, u0, params)
    return selection_function(code, p, factor, params)
