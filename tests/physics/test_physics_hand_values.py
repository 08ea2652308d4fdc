"""Hand values of every kernel, efficiency factor and local-field formula, from the sources.

Each expected value is computed here with plain Python floats from the formula as its source
writes it (docs/physics.md gives the same equations with the readings we chose); the project's
functions are only called to be checked. Sizes and binder contents are unequal on purpose: at
d = d' an error in a size exponent or in the pairing of d and d' cancels.

Sources: seed 000 = Hashemian, Ghanaatpishe, Armaou, "Development of a reduced order model for
bi-component granulation processes via Laguerre polynomials" (eq. numbers as printed);
seed 001 = the QMOM/KTGF thesis (eq. numbers as printed); Hounslow 1998 (EKE kernel);
Sinclair & Jackson 1989 (g0, as OpenFOAM's SinclairJacksonRadial.C evaluates it);
Gidaspow 1994 (collision velocity); Ennis, Tardos & Pfeffer 1991 and Liu et al. 2000 (viscous
Stokes number and its critical value).

Tolerance: every expected value is a few dozen floating-point operations (cube roots, exp, log,
tanh) on inputs whose condition numbers are below 1e2, so the two evaluations differ by at most
~1e-14 relative; rel = 1e-12 leaves a margin and still catches any change of a constant or an
exponent (the smallest change of interest, a 1% constant, is 1e10 times larger).
"""
import math

import numpy as np
import pytest

from pbe_cfd.runs import model
from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.efficiency import success_probability
from pbe_cfd.physics.kernels import KERNELS, collision_frequency, kernel_cell_factor
from pbe_cfd.physics.rates import aggregation_rate, droplet_capture_rate

from conftest import AVICEL, make_scene

REL = 1e-12

# ---- the particles (plain floats) -------------------------------------------------------------
RHO_S = 1021.0                 # Avicel density, seed 000 table II [kg/m3]
RHO_L = 1000.0                 # binder density [kg/m3] (aqueous binder; not given in seed 000)
MU = 0.762                     # binder viscosity, seed 000 table II [Pa s]
B_S, C_S = 35.1, 0.129         # accessible-binder sigmoid b, c, seed 000 table I
F_L, G_L = 25.9, 0.327         # binder-layer correlation f, g, seed 000 table I
H_A = 6.3e-6                   # asperity h_a, seed 000 table I [m]
R_G = 60e-6                    # radius of gyration r_g, seed 000 section II [m]
EPS, S_MAX = 0.4, 0.5          # porosity (seed 001 sec. 6.6: 0.4) and S_max (ours, < 1 to test)
ALPHA_MAX = 0.62               # packing limit of the bundled OpenFOAM case

D1, Y1 = 100.4e-6, 0.08        # a primary-size granule with a little binder (d [m], y = b/p)
D2, Y2 = 260.0e-6, 0.21        # a larger, wetter granule
D_DROP = 60e-6                 # binder droplet, seed 000 table II [m]


def mass_of(d, rho):
    """Mass [kg] of a sphere of diameter d [m] and density rho [kg/m3]."""
    return rho * math.pi / 6.0 * d ** 3


P1, P2 = mass_of(D1, RHO_S), mass_of(D2, RHO_S)
B1, B2 = Y1 * P1, Y2 * P2
PD = mass_of(D_DROP, RHO_L)                      # droplet mass: pure binder at the binder density
# Reading (docs/physics.md, "sizes"): every particle's diameter comes from its total mass at the
# particle density rho_s, a free droplet included (0.7% smaller than its diameter at rho_l).
DD = (6.0 * PD / (math.pi * RHO_S)) ** (1.0 / 3.0)


# ---- the formulas, as the sources write them ---------------------------------------------------
def g0_sinclair_jackson(alpha, alpha_max, alpha_min_friction=None):
    """Seed 001 eq. 4.1.15 (Sinclair & Jackson): g0 = 1/(1 - (a/a_max)^(1/3));
    OpenFOAM's SinclairJacksonRadial.C evaluates it at min(alpha, alphaMinFriction)."""
    if alpha_min_friction is not None:
        alpha = min(alpha, alpha_min_friction)
    return 1.0 / (1.0 - (alpha / alpha_max) ** (1.0 / 3.0))


def collision_velocity(theta):
    """Seed 001 eq. 5.3.13 (Gidaspow 1994): u0 = 4 sqrt(Theta / pi), the mean relative speed of
    two Maxwellian particles with velocity variance Theta per component."""
    return 4.0 * math.sqrt(theta / math.pi)


def eke(k0, d1, d2, d_ref):
    """Seed 001 eq. 5.3.4 (Hounslow 1998), diameters normalised by d_ref:
    beta = k0 (x1 + x2)^2 sqrt(1/x1^3 + 1/x2^3), x = d / d_ref."""
    x1, x2 = d1 / d_ref, d2 / d_ref
    return k0 * (x1 + x2) ** 2 * math.sqrt(1.0 / x1 ** 3 + 1.0 / x2 ** 3)


def ktgf(k0, g0, theta, d43, d1, d2):
    """Seed 001 eq. 5.3.5 (Rajniak et al. 2009 after Goldschmidt 2001), k0 dimensionless:
    beta = k0 g0 d43^(3/2) sqrt(Theta) (d1 + d2)^2 sqrt(1/d1^3 + 1/d2^3)."""
    return (k0 * g0 * d43 ** 1.5 * math.sqrt(theta) * (d1 + d2) ** 2
            * math.sqrt(1.0 / d1 ** 3 + 1.0 / d2 ** 3))


def accessible_binder(y):
    """Seed 000 sec. II "Geometry factor" (Rajniak et al. 2009): eta = 1/(1 + exp(-b (y - c)))."""
    return 1.0 / (1.0 + math.exp(-B_S * (y - C_S)))


def geometric(y1, y2):
    """Seed 000 sec. II, seed 001 eq. 5.3.7: psi_geom = 1 - (1 - eta1)(1 - eta2)."""
    return 1.0 - (1.0 - accessible_binder(y1)) * (1.0 - accessible_binder(y2))


def stokes(u0, d1, d2):
    """Seed 001 eq. 5.3.10-5.3.12 (Ennis et al. 1991): St = 8 m u0 / (3 pi mu d^2) with the
    reduced mass m = m1 m2/(m1 + m2) and reduced diameter d = d1 d2/(d1 + d2); written out, this
    is seed 000 eq. 4, St = 4 rho u0 d1 d2 (d1 + d2)^2 / (9 mu (d1^3 + d2^3))."""
    m1, m2 = mass_of(d1, RHO_S), mass_of(d2, RHO_S)
    m_red = m1 * m2 / (m1 + m2)
    d_red = d1 * d2 / (d1 + d2)
    return 8.0 * m_red * u0 / (3.0 * math.pi * MU * d_red ** 2)


def critical_stokes(y1, y2):
    """Seed 000 eq. 5-6: St* = 2 ln(lambda / h_a), lambda = r_g (phi1^(1/3) + phi2^(1/3)),
    phi = exp(f (y - g)) (Liu et al. 2000, type-2 coalescence; seed 001 eq. 5.3.9)."""
    lam = R_G * (math.exp(F_L * (y1 - G_L)) ** (1.0 / 3.0)
                 + math.exp(F_L * (y2 - G_L)) ** (1.0 / 3.0))
    return 2.0 * math.log(lam / H_A)


def physical(u0, d1, y1, d2, y2, width=0.0):
    """Seed 000 sec. II: 1 if St <= St*, else 0; with width w > 0 our smooth switch
    0.5 (1 - tanh((St - St*) / (w St*))) (docs/physics.md)."""
    st, st_c = stokes(u0, d1, d2), critical_stokes(y1, y2)
    if width == 0.0:
        return 1.0 if st <= st_c else 0.0
    return 0.5 * (1.0 - math.tanh((st - st_c) / (width * st_c)))


def saturation(p1, b1, p2, b2):
    """Seed 001 eq. 6.4.1-6.4.2: S = H rho_s (1 - eps) / (rho_l eps), psi = S / S_max, H the
    binder-to-solid mass ratio; our reading: H of the pair's combined binder and solid, psi
    capped at 1 (docs/physics.md)."""
    h = (b1 + b2) / (p1 + p2 - b1 - b2)
    s = h * RHO_S * (1.0 - EPS) / (RHO_L * EPS)
    return min(1.0, s / S_MAX)


# ---- scenes -> the project's arrays ------------------------------------------------------------
def arrays(kernel="constant", rate=1.0, efficiency=(), droplet_factor=None, width=0.0,
           reference_diameter=None, alpha_min_friction=None, injection=True):
    """params, config of a scene with these physics, through the scene reader and model.pack."""
    material = {**AVICEL, "porosity": EPS, "saturation_max": S_MAX,
                "stokes_switch_width": width}
    aggregation = {"kernel": kernel, "rate": rate, "efficiency": list(efficiency)}
    if droplet_factor is not None:
        aggregation["droplet_factor"] = droplet_factor
    if reference_diameter is not None:
        aggregation["reference_diameter"] = reference_diameter
    domain = {"type": "well-mixed", "alpha_max": ALPHA_MAX, "granular_temperature": 1e-4,
              "solids_fraction": 0.3}
    if alpha_min_friction is not None:
        domain["alpha_min_friction"] = alpha_min_friction
    tables = dict(material={**material, "_replace": True}, aggregation=aggregation,
                  domain={**domain, "_replace": True},
                  initial={"distribution": "monodisperse", "number_density": 1e10,
                           "diameter": D1, "_replace": True})
    if injection:
        tables["binder_injection"] = {"rate": 1e8, "droplet_diameter": D_DROP}
    packed = model.pack(make_scene(**tables))
    return packed.params, packed.config


def kernel_code(name):
    return KERNELS[name][0]


# ---- kernels --------------------------------------------------------------------------------
def test_analytic_kernels_at_unequal_masses():
    for name, k0, expected in (("constant", 3e-12, 3e-12),                 # Smoluchowski
                               ("sum", 7e-3, 7e-3 * (P1 + P2)),            # Golovin 1963
                               ("product", 2e5, 2e5 * P1 * P2)):           # McLeod 1962
        params, _ = arrays(name, k0)
        got = collision_frequency(kernel_code(name), P1, P2, 0.0, 0.0, 0.0, params)
        assert got == pytest.approx(expected, rel=REL, abs=0), name


@pytest.mark.parametrize("reference_diameter", [None, 60e-6])
def test_eke_kernel_at_unequal_sizes(reference_diameter):
    """Reference size: the initial granule (default; the bundled seed scenes) or the binder drop
    (seed 000's normalisation of x43, reference_diameter = d_b)."""
    k0 = 2.5e-14                                  # seed 000 table I [m3/s]
    params, _ = arrays("eke", k0, reference_diameter=reference_diameter)
    d_ref = D1 if reference_diameter is None else reference_diameter
    got = collision_frequency(kernel_code("eke"), P1, P2, 0.0, 0.0, 0.0, params)
    assert got == pytest.approx(eke(k0, D1, D2, d_ref), rel=REL, abs=0)
    # a granule and a droplet (sizes from the mass at rho_s, see DD)
    got = collision_frequency(kernel_code("eke"), P2, PD, 0.0, 0.0, 0.0, params)
    assert got == pytest.approx(eke(k0, D2, DD, d_ref), rel=REL, abs=0)


def test_eke_reference_size_changes_every_rate_by_the_same_factor():
    params_p, _ = arrays("eke", 2.5e-14)
    params_d, _ = arrays("eke", 2.5e-14, reference_diameter=D_DROP)
    for a, b in ((P1, P2), (P1, PD), (P2, 8 * P2)):
        ratio = (collision_frequency(kernel_code("eke"), a, b, 0, 0, 0, params_d)
                 / collision_frequency(kernel_code("eke"), a, b, 0, 0, 0, params_p))
        # the kernel is homogeneous of degree 2 - 3/2 = 1/2 in diameter
        assert ratio == pytest.approx((D1 / D_DROP) ** 0.5, rel=REL, abs=0)
    assert (D1 / D_DROP) ** 0.5 == pytest.approx(1.2936, abs=1e-4)


@pytest.mark.parametrize("alpha,theta,d43", [(0.395, 7.8e-5, 1.3e-4), (0.12, 2.1e-4, 2.2e-4)])
def test_ktgf_kernel_at_unequal_sizes(alpha, theta, d43):
    k0 = 1e-5
    params, _ = arrays("ktgf", k0)
    expected = ktgf(k0, g0_sinclair_jackson(alpha, ALPHA_MAX), theta, d43, D1, D2)
    got = collision_frequency(kernel_code("ktgf"), P1, P2, alpha, theta, d43, params)
    assert got == pytest.approx(expected, rel=REL, abs=0)
    got = collision_frequency(kernel_code("ktgf"), PD, P2, alpha, theta, d43, params)
    assert got == pytest.approx(ktgf(k0, g0_sinclair_jackson(alpha, ALPHA_MAX), theta, d43,
                                     DD, D2), rel=REL, abs=0)


# ---- local fields: g0(alpha), u0(Theta) ---------------------------------------------------
@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.49, 0.53, 0.6])
def test_radial_distribution_with_and_without_the_friction_cap(alpha):
    """The kernel's cell factor k0 g0 sqrt(Theta) d43^(3/2) carries g0; with the scene's
    alpha_min_friction = 0.5 g0 stops at its value at 0.5 (14.45 with alpha_max 0.62)."""
    theta, d43, k0 = 1e-4, 1.5e-4, 1e-5
    for cap in (None, 0.5):
        params, _ = arrays("ktgf", k0, alpha_min_friction=cap)
        got = kernel_cell_factor(kernel_code("ktgf"), alpha, theta, d43, params)
        expected = k0 * g0_sinclair_jackson(alpha, ALPHA_MAX, cap) * math.sqrt(theta) * d43 ** 1.5
        assert got == pytest.approx(expected, rel=REL, abs=0), cap
    assert g0_sinclair_jackson(0.6, ALPHA_MAX, 0.5) == pytest.approx(14.45, abs=0.01)
    assert g0_sinclair_jackson(0.6, ALPHA_MAX) == pytest.approx(91.9, abs=0.1)


@pytest.mark.parametrize("theta", [1.7e-6, 7.8e-5, 2.1e-4, 1.0])
def test_collision_velocity_from_granular_temperature(theta):
    scene = make_scene(domain={"type": "well-mixed", "granular_temperature": theta,
                               "solids_fraction": 0.3})
    cell = model.well_mixed_cell(scene)[0]
    assert cell[P.COLLISION_VELOCITY] == pytest.approx(collision_velocity(theta), rel=REL, abs=0)
    # a given collision velocity wins over Theta
    scene = make_scene(domain={"type": "well-mixed", "granular_temperature": theta,
                               "collision_velocity": 5.5})
    assert model.well_mixed_cell(scene)[0][P.COLLISION_VELOCITY] == 5.5


def test_collision_velocity_of_every_mesh_cell():
    """The coupled run's cell rows and the Laguerre tensor's Theta grid use the same u0(Theta)."""
    from pbe_cfd.io.openfoam import load_snapshot
    from pbe_cfd.runs.domain import build_cells
    from pbe_cfd.methods.laguerre.tensor import theta_to_u0
    from pbe_cfd.physics.kernels import collision_velocity as kernel_u0
    from pbe_cfd.scene.scene import load_scene
    cells = load_snapshot()
    rows = build_cells(load_scene("fluid-bed"), cells)[0]
    theta = np.maximum(np.asarray(cells.theta, dtype=float), 0.0)
    expected = np.array([collision_velocity(t) for t in theta])
    assert np.all(np.abs(rows[:, P.COLLISION_VELOCITY] - expected) <= REL * expected)
    assert np.count_nonzero(expected > 0) > 100
    for t in (1e-6, 7.8e-5, 1.0):
        assert float(theta_to_u0(t)) == pytest.approx(collision_velocity(t), rel=REL, abs=0)
        assert float(kernel_u0(t)) == pytest.approx(collision_velocity(t), rel=REL, abs=0)


# ---- efficiency factors --------------------------------------------------------------------
def only(factor, **kw):
    return arrays("constant", 1.0, efficiency=(factor,), **kw)


@pytest.mark.parametrize("y1,y2", [(Y1, Y2), (0.0, 0.35), (0.129, 0.5), (0.02, 1.0)])
def test_geometric_factor(y1, y2):
    params, config = only("geometric")
    got = success_probability(P1, y1 * P1, P2, y2 * P2, 1.0, params, config)
    assert got == pytest.approx(geometric(y1, y2), rel=REL, abs=0)


def test_stokes_criterion_sharp():
    """Below, at and above the critical Stokes number of the unequal pair (d1, y1), (d2, y2)."""
    params, config = only("physical")
    u_edge = critical_stokes(Y1, Y2) / stokes(1.0, D1, D2)      # St is linear in u0
    assert 5.5 < u_edge < 50.0                                  # the seed's u0 = 5.5 m/s is below
    for u0, expected in ((5.5, 1.0), (0.98 * u_edge, 1.0), (1.02 * u_edge, 0.0)):
        got = success_probability(P1, B1, P2, B2, u0, params, config)
        assert got == physical(u0, D1, Y1, D2, Y2) == expected, u0
    # a dry pair of primary granules rebounds at u0 = 5.5 m/s (St 0.66 > St* 0.25)
    assert stokes(5.5, D1, D1) > critical_stokes(0.0, 0.0) > 0.0
    assert success_probability(P1, 0.0, P1, 0.0, 5.5, params, config) == 0.0


@pytest.mark.parametrize("ratio", [0.7, 0.95, 1.0, 1.1, 1.6])
def test_stokes_criterion_smooth_switch(ratio):
    """The smooth switch is a continuous function of St/St*, so it checks the constants of St
    and St* at any velocity, not only across the step."""
    width = 0.2
    params, config = only("physical", width=width)
    u0 = ratio * critical_stokes(Y1, Y2) / stokes(1.0, D1, D2)
    got = success_probability(P1, B1, P2, B2, u0, params, config)
    assert got == pytest.approx(physical(u0, D1, Y1, D2, Y2, width), rel=REL, abs=1e-15)
    assert stokes(u0, D1, D2) / critical_stokes(Y1, Y2) == pytest.approx(ratio, rel=REL, abs=0)


@pytest.mark.parametrize("y1,y2", [(Y1, Y2), (0.0, 0.02), (0.3, 0.6)])
def test_saturation_factor(y1, y2):
    params, config = only("saturation")
    got = success_probability(P1, y1 * P1, P2, y2 * P2, 1.0, params, config)
    assert got == pytest.approx(saturation(P1, y1 * P1, P2, y2 * P2), rel=REL, abs=0)
    assert 0.0 < got <= 1.0


# ---- the rates the methods use ------------------------------------------------------------
def test_aggregation_rate_multiplies_kernel_and_every_factor():
    k0, alpha, theta, d43 = 1e-5, 0.3, 1.2e-4, 1.4e-4
    u0 = collision_velocity(theta)
    params, config = arrays("ktgf", k0, efficiency=("geometric", "physical", "saturation"))
    expected = (ktgf(k0, g0_sinclair_jackson(alpha, ALPHA_MAX), theta, d43, D1, D2)
                * geometric(Y1, Y2) * physical(u0, D1, Y1, D2, Y2)
                * saturation(P1, B1, P2, B2))
    got = aggregation_rate(P1, B1, P2, B2, alpha, theta, u0, d43, params, config)
    assert got == pytest.approx(expected, rel=REL, abs=0)
    assert expected > 0


@pytest.mark.parametrize("kernel", ["eke", "ktgf"])
def test_droplet_capture_rate(kernel):
    """Seed 000 sec. II: a granule meets a pure binder droplet (p_d, b = p_d) at 100 times the
    kernel, times the success probability of the granule-droplet pair."""
    factor = 100.0
    k0 = {"eke": 2.5e-14, "ktgf": 1e-5}[kernel]
    alpha, theta, d43 = 0.4, 5e-5, 1.6e-4
    params, config = arrays(kernel, k0, efficiency=("geometric", "physical", "saturation"),
                            droplet_factor=factor)
    for u0 in (collision_velocity(theta), 5.5):
        beta = (eke(k0, D2, DD, D1) if kernel == "eke"
                else ktgf(k0, g0_sinclair_jackson(alpha, ALPHA_MAX), theta, d43, D2, DD))
        psi = geometric(Y2, 1.0) * physical(u0, D2, Y2, DD, 1.0) * saturation(P2, B2, PD, PD)
        got = droplet_capture_rate(P2, B2, alpha, theta, u0, d43, params, config)
        assert got == pytest.approx(factor * beta * psi, rel=REL, abs=0), u0
    # the droplet mass the scene gives the physics: pure binder at the binder density
    assert params[P.DROPLET_MASS] == pytest.approx(PD, rel=REL, abs=0)
    assert params[P.DROPLET_FACTOR] == factor
