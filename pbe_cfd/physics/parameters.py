"""Layout of the flat parameter arrays handed to the numba physics and methods.

numba kernels take plain arrays and floats. The orchestration layer (``pbe_cfd.runs.model``)
packs a scene into three arrays whose slots are named here:

``params`` (float64, SI units unless stated)
    material, kernel and efficiency constants and the scales used to non-dimensionalise.
``config`` (int64)
    switches: kernel code, which efficiency factors apply, droplet rules, method code and sizes.
``cell`` (float64, one row per mesh cell)
    local fields: solids fraction, granular temperature, collision velocity, injection rate.
"""

# ---- params (float64) -------------------------------------------------------------------
RATE = 0                 # k0 of the kernel (units depend on kernel, see physics.kernels)
DENSITY = 1              # particle (solid) density rho_s [kg/m3]
BINDER_DENSITY = 2       # binder liquid density rho_l [kg/m3]
BINDER_VISCOSITY = 3     # binder viscosity mu [Pa s]
REFERENCE_VOLUME = 4     # v_ref of the eke kernel [m3]
ALPHA_MAX = 5            # packing limit of the radial distribution function [-]
GEO_SLOPE = 6            # b_s of the accessible-binder sigmoid [-]
GEO_CENTRE = 7           # c_s of the accessible-binder sigmoid [-]
PHI_SLOPE = 8            # f of the binder-layer correlation [-]
PHI_CENTRE = 9           # g of the binder-layer correlation [-]
ASPERITY = 10            # h_a surface asperity height [m]
GYRATION_RADIUS = 11     # r_g mean radius of gyration [m]
STOKES_WIDTH = 12        # relative width of the smooth Stokes switch [-] (0 = sharp step)
POROSITY = 13            # granule porosity eps for the saturation efficiency [-]
SATURATION_MAX = 14      # S_max of the saturation efficiency [-]
DROPLET_FACTOR = 15      # droplet-granule kernel multiplier [-] (0 = droplets are ordinary)
DROPLET_MASS = 16        # mass of one binder droplet p_d [kg]
NUMBER_SCALE = 17        # number-density scale N_ref [1/m3] (non-dimensionalisation)
MASS_SCALE = 18          # particle-mass scale p_ref [kg] (non-dimensionalisation)
STEP_FLOOR = 19          # smallest step the integrator may take before it reports a stall [s]
ALPHA_MIN_FRICTION = 20  # g0 is evaluated at min(alpha, this) as OpenFOAM's radial models do [-]
BREAKAGE_RATE = 21       # s0 of the breakage selection [1/s] (physics.breakage)
BREAKAGE_EXPONENT = 22   # a of S = s0 (p / p_ref)^a [-]
BREAKAGE_REFERENCE_MASS = 23    # p_ref of the selection [kg]
BREAKAGE_REFERENCE_THETA = 24   # Theta_ref of the collisional selection [m2/s2]
YIELD_STRENGTH = 25      # granule yield strength Y of the Stokes deformation number [Pa] (0: no gate)
CRITICAL_DEFORMATION = 26       # critical Stokes deformation number St_def* [-]
N_PARAMS = 27

# ---- config (int64) ---------------------------------------------------------------------
KERNEL = 0               # code of the collision kernel (physics.kernels.KERNEL_REGISTRY)
SEPARATE_DROPLETS = 1    # 1 if droplets are a population of their own (droplet_factor set)
BIVARIATE = 2            # 1 if binder mass is a coordinate (otherwise univariate in p)
METHOD = 3               # code of the moment method (methods.dispatch)
ORDER = 4                # QMOM nodes N, or Laguerre order m
N_STATE = 5              # length of one cell's state vector
BINDER_NODES = 6         # CQMOM conditional nodes N2 per size node
BREAKAGE = 7             # 1 if a [breakage] table is present (physics.breakage)
BREAKAGE_SELECTION = 8   # code of the breakage selection function (physics.breakage)
BREAKAGE_DAUGHTERS = 9   # code of the breakage daughter rule (physics.breakage)
INTEGRATOR = 10          # per-cell time integrator: 0 explicit, 1 implicit, 2 auto (integrate)
N_SWITCHES_START = 11    # a new single slot goes above this line and moves this number up
# config[EFFICIENCY_SWITCHES + code] = 1: the efficiency factor of that code applies
# (physics.efficiency.EFFICIENCY_REGISTRY); room for MAX_EFFICIENCIES factors
EFFICIENCY_SWITCHES = N_SWITCHES_START
MAX_EFFICIENCIES = 8
USE_GEOMETRIC = EFFICIENCY_SWITCHES + 0    # the geometric (accessible binder) factor
USE_PHYSICAL = EFFICIENCY_SWITCHES + 1     # the viscous Stokes factor
USE_SATURATION = EFFICIENCY_SWITCHES + 2   # the liquid-saturation factor
N_CONFIG = EFFICIENCY_SWITCHES + MAX_EFFICIENCIES

# ---- cell (float64, per cell) ----------------------------------------------------------
ALPHA = 0                # solids volume fraction [-]
THETA = 1                # granular temperature [m2/s2]
COLLISION_VELOCITY = 2   # u0 of the Stokes number [m/s]
INJECTION = 3            # droplet injection rate [droplets/(m3 s)]
N_CELL = 4
