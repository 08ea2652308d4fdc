"""Layout of the flat parameter arrays handed to the numba physics and methods.

numba kernels take plain arrays and floats. The orchestration layer (``pbe_cfd.model``) packs a
scene into three arrays whose slots are named here:

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
N_PARAMS = 21

# ---- config (int64) ---------------------------------------------------------------------
KERNEL = 0               # code of the collision kernel (physics.kernels.KERNELS)
USE_GEOMETRIC = 1        # 1 if the geometric (accessible binder) factor applies
USE_PHYSICAL = 2         # 1 if the viscous Stokes factor applies
USE_SATURATION = 3       # 1 if the liquid-saturation factor applies
SEPARATE_DROPLETS = 4    # 1 if droplets are a population of their own (droplet_factor set)
BIVARIATE = 5            # 1 if binder mass is a coordinate (otherwise univariate in p)
METHOD = 6               # code of the moment method (methods.dispatch)
ORDER = 7                # QMOM nodes N, or Laguerre order m
N_STATE = 8              # length of one cell's state vector
INTEGRATOR = 9           # per-cell time integrator: 0 explicit, 1 implicit, 2 auto (integrate)
N_CONFIG = 10

# ---- cell (float64, per cell) ----------------------------------------------------------
ALPHA = 0                # solids volume fraction [-]
THETA = 1                # granular temperature [m2/s2]
COLLISION_VELOCITY = 2   # u0 of the Stokes number [m/s]
INJECTION = 3            # droplet injection rate [droplets/(m3 s)]
N_CELL = 4
