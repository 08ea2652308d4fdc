"""The three cases of docs/results/psd.md (fixed before any run), as the independent
reference's specs (tests/references/cnmc_particles.py) and as scene tables of pbe_cfd.

seed: seed-wurster.toml's physics (docs/physics.md section 12) at 600 s; sum-a1-uniform and
eke-a1/3-equal: exponential start N0 = 1e10 /m3, mean P0 = 1e-9 kg, rho = 1000 kg/m3, dry,
power selection S = 1 /s (p / P0)^a, at 5 s.
"""
import math

SEED_RHO, SEED_D0, SEED_C0 = 1021.0, 100.4e-6, 3.30e10
SEED_P0 = math.pi / 6.0 * SEED_RHO * SEED_D0 ** 3
DROPLET_D, BINDER_RHO = 60e-6, 1000.0
N0, P0, RHO, S0 = 1.0e10, 1.0e-9, 1000.0, 1.0
END = {"seed": 600.0, "sum-a1-uniform": 5.0, "eke-a1/3-equal": 5.0}
CASES = tuple(END)
#: particles, replicas and first seed of the reference per case (seeds fixed before looking)
REFERENCE_RUN = {"seed": (4000, 16, 27001), "sum-a1-uniform": (4000, 16, 27101),
                 "eke-a1/3-equal": (4000, 16, 27201)}
_BREAKAGE = {"sum-a1-uniform": ("sum", 0.05, 1.0, "uniform"),
             "eke-a1/3-equal": ("eke", 1.77e-11, 1.0 / 3.0, "equal")}


def reference_spec(case):
    """The case as a spec of cnmc_particles.simulate (SI units)."""
    if case == "seed":
        return {"rho": SEED_RHO, "kernel": "eke", "k0": 2.5e-14, "p_ref": SEED_P0,
                "efficiency": {"geometric": True, "physical": True, "bs": 35.1, "cs": 0.129,
                               "f": 25.9, "g": 0.327, "h_a": 6.3e-6, "r_g": 60e-6,
                               "u0": 5.5, "mu": 0.762},
                "droplets": {"p_d": math.pi / 6.0 * BINDER_RHO * DROPLET_D ** 3,
                             "factor": 100.0, "rate": 1.485e8, "nd0": 1.485e9},
                "initial": {"distribution": "monodisperse", "mass": SEED_P0,
                            "number_density": SEED_C0, "binder_fraction": 0.0}}
    kernel, k0, a, daughters = _BREAKAGE[case]
    return {"rho": RHO, "kernel": kernel, "k0": k0, "p_ref": P0,
            "breakage": {"s0": S0, "exponent": a, "p_ref": P0, "daughters": daughters},
            "initial": {"distribution": "exponential", "mean": P0, "number_density": N0}}


def scene_tables(case):
    """(scene path or None, make_scene keyword tables) of the case for pbe_cfd."""
    if case == "seed":
        return "seed-wurster", {}
    kernel, k0, a, daughters = _BREAKAGE[case]
    d_ref = (6.0 * P0 / (math.pi * RHO)) ** (1.0 / 3.0)
    agg = {"kernel": kernel, "rate": k0}
    if kernel == "eke":
        agg["reference_diameter"] = d_ref
    return None, {"scene": {"end_time": END[case], "output_interval": END[case] / 4},
                  "material": {"density": RHO},
                  "initial": {"distribution": "exponential", "number_density": N0,
                              "mean_mass": P0},
                  "aggregation": agg,
                  "breakage": {"selection": "power", "rate": S0, "exponent": a,
                               "reference_mass": P0, "daughters": daughters}}
