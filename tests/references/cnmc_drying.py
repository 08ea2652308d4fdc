"""Independent reference for spraying and drying with aggregation: a constant-number Monte
Carlo of granules (p, b) (Smith and Matsoukas 1998) whose liquid b evaporates between events.

Written from docs/physics.md sections 7 and 15 alone, in numpy, sharing no code with pbe_cfd.
The gas side enters as four numbers of the scene's air (rho_g [kg/m3], mu_g [Pa s], D_v
[m2/s], the driving force Y_s(T_wb) - Y [-]); everything a method does with them is written
out here again:

- a particle (p, b) of dry mass m = p - b loses liquid at
  e = pi d Sh D_v rho_g dY min(1, (X - X_eq) / (X_cr - X_eq)),  X = b / m,
  Sh = 2 + 0.6 Re^(1/2) Sc^(1/3), Re = rho_g u d / mu_g, Sc = mu_g / (rho_g D_v),
  d = max((6 m / (pi rho_s))^(1/3), (6 b / (pi rho_l))^(1/3)); dp/dt = db/dt = -e;
- aggregation at the constant kernel k0 per unordered pair / V: (p_i + p_j, b_i + b_j) takes
  slot i, slot j gets a copy of a particle drawn among the other N - 1;
- spraying: droplets of a solution (mass p_d, liquid (1 - s) p_d) arrive as ordinary particles
  at R V [1/s] while the spray is on (t in [start, stop)); each is added and then one of the
  N + 1 particles drawn uniformly is removed.

The box's volume follows from the mass balance, which is known: the mass concentration is
C(t) = n0 p0 + R p_d t_on(t) - E(t) (t_on the time sprayed so far), so after every event
V = P / C(t), P the box's mass (Smith and Matsoukas 1998, eqs. 18-19, with the sprayed mass at
its expectation); M10 is then exact and the other moments' scatter is smaller than with the
number-based rescaling.

Between events every particle's liquid is advanced by classical RK4 on the whole box at once
(steps of at most a fifth of the smallest liquid time b / e of the wet particles, and never
across an event or an output time); the waiting times are exponential at the total rate,
which is constant between events (the drift changes no event rate of the constant kernel).
The evaporated liquid E [kg/m3] sums the box's losses over its volume.

Units: SI throughout (kg, m, s, 1/m3).
"""
import numpy as np


def _rate(p, b, case):
    """Evaporation rate e [kg/s] of particles (p, b) [kg] (module docstring)."""
    g = case["gas"]
    dry = p - b
    d = np.maximum(np.cbrt(6.0 * dry / (np.pi * case["rho_s"])),
                   np.cbrt(6.0 * np.maximum(b, 0.0) / (np.pi * case["rho_l"])))
    re = g["rho"] * case["slip"] * d / g["mu"]
    sc = g["mu"] / (g["rho"] * g["diffusivity"])
    e = np.pi * d * (2.0 + 0.6 * np.sqrt(re) * np.cbrt(sc)) * g["diffusivity"] * g["rho"] * \
        g["driving"]
    x = np.where(dry > 0, b / np.where(dry > 0, dry, 1.0), np.inf)
    falling = np.clip((x - case["x_eq"]) / (case["x_cr"] - case["x_eq"]), 0.0, 1.0)
    return np.where(b > 0, e * falling, 0.0)


def _dry(p, b, dt, case):
    """Advance every particle's liquid by dt [s] (RK4 sub-steps); returns (p, b, lost [kg])."""
    b0 = b.sum()
    left = dt
    while left > 0.0:
        e = _rate(p, b, case)
        wet = e > 0
        if not np.any(wet):
            break
        h = min(left, 0.2 * np.min(b[wet] / e[wet]))
        dry = p - b
        k1 = -e
        k2 = -_rate(dry + np.maximum(b + 0.5 * h * k1, 0), np.maximum(b + 0.5 * h * k1, 0), case)
        k3 = -_rate(dry + np.maximum(b + 0.5 * h * k2, 0), np.maximum(b + 0.5 * h * k2, 0), case)
        k4 = -_rate(dry + np.maximum(b + h * k3, 0), np.maximum(b + h * k3, 0), case)
        b = np.maximum(b + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0, 0.0)
        p = dry + b
        left -= h
    return p, b, b0 - b.sum()


#: the moments M_ij [kg^(i+j)/m3] of ``ensemble`` (i < 6, j < 4), then the evaporated liquid
#: [kg/m3]
ORDERS = tuple((i, j) for i in range(6) for j in range(4))
NAMES = tuple(f"M{i}{j}" for i, j in ORDERS) + ("liquid_evaporated",)


def _moments(p, b, vol, evaporated):
    return np.array([np.sum(p ** i * b ** j) / vol for i, j in ORDERS] + [evaporated])


def _sprayed(case, t):
    """Mass sprayed by t [s], per m3 [kg/m3]."""
    return max(0.0, min(t, case["stop"]) - case["start"]) * case["rate"] * case["droplet_mass"]


def run_box(case, n_particles, times, rng):
    """One replica: the NAMES at ``times`` [s] (from 0, increasing)."""
    n = n_particles
    p = np.full(n, case["p0"])
    b = case["y0"] * p
    vol = n / case["n0"]
    conc0 = case["n0"] * case["p0"]
    pd = case["droplet_mass"]
    bd = (1.0 - case["solids_fraction"]) * pd
    evaporated = 0.0
    out = np.zeros((len(times), len(NAMES)))
    t = 0.0
    k_out = 0
    while k_out < len(times):
        spraying = case["start"] <= t < case["stop"]
        r_agg = 0.5 * case["k0"] * n * (n - 1) / vol
        r_inj = case["rate"] * vol if spraying else 0.0
        r = r_agg + r_inj
        t_event = t + rng.exponential(1.0 / r) if r > 0 else np.inf
        # the spray switches at start and stop: the rate changes there
        switch = min((s for s in (case["start"], case["stop"]) if s > t), default=np.inf)
        t_stop = min(t_event, switch, times[k_out])
        # the volume at t_stop of the box before it dries (the spray's mass at its
        # expectation), then the loss in that volume
        vol = p.sum() / (conc0 + _sprayed(case, t_stop) - evaporated)
        p, b, lost = _dry(p, b, t_stop - t, case)
        evaporated += lost / vol
        t = t_stop
        if t_stop == times[k_out]:
            out[k_out] = _moments(p, b, vol, evaporated)
            k_out += 1
            continue
        if t_stop == switch:
            continue
        if rng.random() * r < r_agg:
            i, j = rng.choice(n, 2, replace=False)
            p[i] += p[j]
            b[i] += b[j]
            k = rng.integers(n - 1)
            k = k + 1 if k >= j else k
            p[j], b[j] = p[k], b[k]
        else:
            k = rng.integers(n + 1)
            if k < n:                       # the droplet stays, particle k leaves
                p[k], b[k] = pd, bd
        vol = p.sum() / (conc0 + _sprayed(case, t) - evaporated)
    return out


def ensemble(case, n_particles, replicas, seed, times):
    """(mean, 95% half-width) over ``replicas`` boxes of the NAMES at ``times`` [s]; seeds
    from numpy's SeedSequence(seed)."""
    runs = np.array([run_box(case, n_particles, times, np.random.default_rng(s))
                     for s in np.random.SeedSequence(seed).spawn(replicas)])
    half = 2.0 * runs.std(axis=0, ddof=1) / np.sqrt(replicas)
    return runs.mean(axis=0), half
