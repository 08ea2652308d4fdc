"""Layout of the flat parameter arrays handed to the numba physics and methods.

numba kernels take plain arrays and floats. The orchestration layer (``pbe_cfd.runs.model``)
packs a scene into three arrays whose slots are named here:

``params`` (float64, SI units unless stated)
    material, kernel and efficiency constants and the scales used to non-dimensionalise.
``config`` (int64)
    switches: kernel code, which efficiency factors apply, droplet rules, method code and sizes.
``cell`` (float64, one row per mesh cell)
    local fields: solids fraction, granular temperature, collision velocity, injection rate,
    and the drying's gas where it comes from the CFD (slip velocity, the gas state).
"""


def numbered(table, namespace, start=0) -> int:
    """Give each name of ``table`` ((name, description) pairs, in order) the next slot number
    in ``namespace`` (a module's globals), from ``start``; returns the slot after the last.
    Slot numbers are never written by hand: adding a slot is one more entry of its table."""
    for offset, (name, _) in enumerate(table):
        if name in namespace:
            raise ValueError(f"slot {name} is named twice")
        namespace[name] = start + offset
    return start + len(table)


# ---- params (float64) -------------------------------------------------------------------
PARAMS = (
    ("RATE", "k0 of the kernel (units depend on kernel, see physics.kernels)"),
    ("DENSITY", "particle (solid) density rho_s [kg/m3]"),
    ("BINDER_DENSITY", "binder liquid density rho_l [kg/m3]"),
    ("BINDER_VISCOSITY", "binder viscosity mu [Pa s]"),
    ("REFERENCE_VOLUME", "v_ref of the eke kernel [m3]"),
    ("ALPHA_MAX", "packing limit of the radial distribution function [-]"),
    ("GEO_SLOPE", "b_s of the accessible-binder sigmoid [-]"),
    ("GEO_CENTRE", "c_s of the accessible-binder sigmoid [-]"),
    ("PHI_SLOPE", "f of the binder-layer correlation [-]"),
    ("PHI_CENTRE", "g of the binder-layer correlation [-]"),
    ("ASPERITY", "h_a surface asperity height [m]"),
    ("GYRATION_RADIUS", "r_g mean radius of gyration [m]"),
    ("STOKES_WIDTH", "relative width of the smooth Stokes switch [-] (0 = sharp step)"),
    ("POROSITY", "granule porosity eps for the saturation efficiency [-]"),
    ("SATURATION_MAX", "S_max of the saturation efficiency [-]"),
    ("DROPLET_FACTOR", "droplet-granule kernel multiplier [-] (0 = droplets are ordinary)"),
    ("DROPLET_MASS", "mass of one binder droplet p_d [kg]"),
    ("NUMBER_SCALE", "number-density scale N_ref [1/m3] (non-dimensionalisation)"),
    ("MASS_SCALE", "particle-mass scale p_ref [kg] (non-dimensionalisation)"),
    ("STEP_FLOOR", "smallest step the integrator may take before it reports a stall [s]"),
    ("ALPHA_MIN_FRICTION", "g0 is evaluated at min(alpha, this) as OpenFOAM's radial models do "
                           "[-]"),
    ("BREAKAGE_RATE", "s0 of the breakage selection [1/s] (physics.breakage)"),
    ("BREAKAGE_EXPONENT", "a of S = s0 (p / p_ref)^a [-]"),
    ("BREAKAGE_REFERENCE_MASS", "p_ref of the selection [kg]"),
    ("BREAKAGE_REFERENCE_THETA", "Theta_ref of the collisional selection [m2/s2]"),
    ("YIELD_STRENGTH", "granule yield strength Y of the Stokes deformation number [Pa] (0: no "
                       "gate)"),
    ("CRITICAL_DEFORMATION", "critical Stokes deformation number St_def* [-]"),
    ("DROPLET_SOLIDS", "solids fraction s of the sprayed binder [-]: a droplet holds liquid "
                       "b_d = (1 - s) p_d (0: pure liquid; physics.injection)"),
    ("DRY_DRIVING", "D_v rho_g (Y_s(T_wb) - Y) of the drying air [kg/(m s)] (physics.drying)"),
    ("DRY_RE", "rho_g / mu_g of the air [s/m2]: Re = DRY_RE u_slip d"),
    ("DRY_SCHMIDT", "Schmidt number mu_g / (rho_g D_v) of water vapour in the air [-]"),
    ("DRY_CRITICAL", "critical moisture X_cr [kg liquid / kg dry solids]"),
    ("DRY_EQUILIBRIUM", "equilibrium moisture X_eq [kg liquid / kg dry solids]"),
    ("DRY_SLIP", "gas-particle slip velocity of the Sherwood number [m/s]"),
)
N_PARAMS = numbered(PARAMS, globals())

# ---- the switch memory of the sharp viscous Stokes step (float64, after the params) -------
# The integrator hands the rates a per-cell copy of params extended by these slots
# (``integrate.cell``): with STOKES_HOLD = 1 the decision psi_p in {0, 1} of each pair of
# property rows (a, c), a, c < HELD_ROWS, is held as first evaluated (-1: not yet) until the
# integrator releases it, so that the rates are smooth within a step; a stage whose own
# decision differs sets STOKES_CROSSED (physics.efficiency.held_decision)
HELD = (
    ("STOKES_HOLD", "1: the sharp Stokes decisions of the pairs are held, 0: evaluated anew"),
    ("STOKES_CROSSED", "set to 1 by a rate evaluation whose own decision differs from the "
                       "held one (a pair crossed St = St*)"),
)
STOKES_HELD = numbered(HELD, globals(), N_PARAMS)
#: property rows whose pairs have a held decision (more rows: evaluated anew, not held)
HELD_ROWS = 40
#: length of the extended per-cell params: decision of rows (a, c) at STOKES_HELD + a HELD_ROWS + c
N_PARAMS_HELD = STOKES_HELD + HELD_ROWS * HELD_ROWS

# ---- config (int64) ---------------------------------------------------------------------
CONFIG = (
    ("KERNEL", "code of the collision kernel (physics.kernels.KERNEL_REGISTRY)"),
    ("SEPARATE_DROPLETS", "1 if droplets are a population of their own (droplet_factor set)"),
    ("BIVARIATE", "1 if binder mass is a coordinate (otherwise univariate in p)"),
    ("METHOD", "code of the moment method (methods.dispatch)"),
    ("ORDER", "QMOM nodes N, or Laguerre order m"),
    ("N_STATE", "length of one cell's state vector"),
    ("BINDER_NODES", "CQMOM conditional nodes N2 per size node"),
    ("BREAKAGE", "1 if a [breakage] table is present (physics.breakage)"),
    ("BREAKAGE_SELECTION", "code of the breakage selection function (physics.breakage)"),
    ("BREAKAGE_DAUGHTERS", "code of the breakage daughter rule (physics.breakage)"),
    ("INTEGRATOR", "per-cell time integrator: 0 explicit, 1 implicit, 2 auto (integrate)"),
    ("DRYING", "1 if a [drying] table is present: the state holds the evaporated liquid"),
    ("DROPLET_LIQUID", "1 if the state carries the free droplets' liquid (entry N_STATE - 3: "
                       "drying with droplets of their own, which then evaporate)"),
    ("DRYING_CELL_SLIP", "1: the drying's slip velocity is the cell row's SLIP_VELOCITY (the "
                         "CFD's), 0: params[DRY_SLIP] (the scene's)"),
    ("DRYING_CELL_AIR", "1: the drying air's GAS_DRIVING, GAS_REYNOLDS, GAS_SCHMIDT are the "
                        "cell row's (the CFD's gas temperature), 0: params' (the scene's)"),
)
#: a new single slot is one more name in CONFIG; the efficiency switches follow them
N_SWITCHES_START = numbered(CONFIG, globals())
# config[EFFICIENCY_SWITCHES + code] = 1: the efficiency factor of that code applies
# (physics.efficiency.EFFICIENCY_REGISTRY); room for MAX_EFFICIENCIES factors
EFFICIENCY_SWITCHES = N_SWITCHES_START
MAX_EFFICIENCIES = 8
#: the switch of each efficiency factor, in the order of the factors' codes (the switch of
#: code k is EFFICIENCY_SWITCHES + k); a new factor is one more name here
EFFICIENCY_FACTORS = (
    ("USE_GEOMETRIC", "the geometric (accessible binder) factor"),
    ("USE_PHYSICAL", "the viscous Stokes factor"),
    ("USE_SATURATION", "the liquid-saturation factor"),
)
if len(EFFICIENCY_FACTORS) > MAX_EFFICIENCIES:
    raise ValueError(f"{len(EFFICIENCY_FACTORS)} efficiency factors, room for {MAX_EFFICIENCIES}")
numbered(EFFICIENCY_FACTORS, globals(), EFFICIENCY_SWITCHES)
N_CONFIG = EFFICIENCY_SWITCHES + MAX_EFFICIENCIES

# ---- cell (float64, per cell) ----------------------------------------------------------
CELL = (
    ("ALPHA", "solids volume fraction [-]"),
    ("THETA", "granular temperature [m2/s2]"),
    ("COLLISION_VELOCITY", "u0 of the Stokes number [m/s]"),
    ("INJECTION", "droplet injection rate [droplets/(m3 s)]"),
    ("SLIP_VELOCITY", "gas-particle slip velocity |U_gas - U_solids| of the drying's Sherwood "
                      "number [m/s] (read with config DRYING_CELL_SLIP)"),
    ("GAS_DRIVING", "D_v rho_g (Y_s(T_wb) - Y) of the cell's gas [kg/(m s)] (read with config "
                    "DRYING_CELL_AIR; as params' DRY_DRIVING)"),
    ("GAS_REYNOLDS", "rho_g / mu_g of the cell's gas [s/m2] (as params' DRY_RE)"),
    ("GAS_SCHMIDT", "Schmidt number of water vapour in the cell's gas [-] (as DRY_SCHMIDT)"),
)
N_CELL = numbered(CELL, globals())

