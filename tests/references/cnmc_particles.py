"""Independent reference for size distributions: a constant-number Monte Carlo (Smith and
Matsoukas 1998; Lin, Lee and Matsoukas 2002) that returns its particle lists.

Written from the text of docs/physics.md alone (sections 2-8), in numpy, sharing no code with
pbe_cfd (nor with the other references). A box of volume V [m3] holds N granules (p_i, b_i)
[kg]; free binder droplets (pure binder of mass p_d, never meeting each other, section 7) are a
number density n_d [1/m3]. Every event is a jump of the box's Markov process, waiting times
exponential with the total rate:

- aggregation of granules i, j at beta(p_i, p_j) psi(i, j) / V per unordered pair:
  (p_i + p_j, b_i + b_j) takes slot i, slot j gets a copy of a granule drawn uniformly among
  the other N - 1 (the population thinned back to N);
- capture of a droplet by granule i at f beta(p_i, p_d) psi(i, droplet) n_d:
  (p_i + p_d, b_i + p_d), n_d -> n_d - 1 / V;
- injection of a droplet at R V: n_d -> n_d + 1 / V;
- breakage of granule i at S(p_i) = s0 (p_i / p_ref)^a into (u p_i, u b_i) and
  ((1 - u) p_i, (1 - u) b_i), u uniform on (0, 1) (``uniform``) or 1/2 (``equal``); the first
  takes slot i, the second replaces a granule drawn uniformly among the N + 1 (dropped if it
  draws itself).

The box volume then follows the exact granule mass concentration (Smith and Matsoukas' volume
rule with the mass balance, docs/physics.md section 9): after every event V = (box mass) /
C_g, C_g = M10(0) + p_d (n_d(0) + R t - n_d) (aggregation and breakage keep mass; the free
droplets' mass is injected minus captured), so the box's M10 is exact and the rates that read
it (the sum kernel) are not driven by the random walk of V a pure number rule gives.

Kernels (section 4): constant k0; sum k0 (p + p'); eke k0 (u^(1/3) + u'^(1/3))^2
sqrt(1/u + 1/u'), u = p / p_ref. Success probability (section 6): geometric
1 - (1 - eta)(1 - eta'), eta = 1 / (1 + exp(-bs (y - cs))), y = b / p; physical: 1 if
St <= St*, else 0, St = 4 rho u0 d d' (d + d')^2 / (9 mu (d^3 + d'^3)), St* = 2 ln(lambda/h_a)
(0 where lambda <= h_a), lambda = r_g (phi^(1/3) + phi'^(1/3)), phi = exp(f (y - g)); every
diameter from its mass at the particle density rho (section 3), droplets included.

Aggregation pairs are drawn from a majorant that is a sum of products of per-granule weights,
w(i, j) = sum_t A_t[i] C_t[j] over ordered pairs with w(i, j) + w(j, i) >= beta psi (exact
sampling, then acceptance beta psi / (w(i, j) + w(j, i))): constant k0/2; sum k0 p_i; eke
2 k0 (u_i^(1/6) + u_i^(2/3) u_j^(-1/2)) (from (a + b)^2 <= 2 (a^2 + b^2) and
sqrt(x + y) <= sqrt(x) + sqrt(y)); with the geometric factor every term is multiplied by
eta_i + eta_j >= 1 - (1 - eta_i)(1 - eta_j). Finite-N bias is O(1/N).

Units: masses [kg], diameters [m], densities [1/m3], rho [kg/m3], k0 [m3/s] (sum:
[m3/(kg s)]), s0 [1/s], R [1/(m3 s)], u0 [m/s], mu [Pa s], h_a, r_g [m].
"""
import math

import numpy as np

#: every this many events the running weight sums are recomputed from scratch (round-off)
RESUM = 2000
#: t_{0.975, R-1} for R = 2 .. 64 replicas (two-sided 95%): table of Student's t
_T975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306,
         9: 2.262, 10: 2.228, 11: 2.201, 12: 2.179, 13: 2.160, 14: 2.145, 15: 2.131,
         16: 2.120, 17: 2.110, 18: 2.101, 19: 2.093, 20: 2.086, 24: 2.064, 31: 2.040,
         32: 2.037, 63: 1.998}


def t975(dof):
    """Student's t quantile 0.975 for dof degrees of freedom (the nearest tabulated below)."""
    keys = [k for k in _T975 if k <= dof]
    return _T975[max(keys)]


def diameter(p, rho):
    """Diameter [m] of mass p [kg] at density rho [kg/m3]."""
    return np.cbrt(6.0 * np.asarray(p, dtype=float) / (math.pi * rho))


class _Physics:
    """Rates of one scenario (``spec``: see ``simulate``)."""

    def __init__(self, spec):
        self.s = spec
        self.kernel = spec["kernel"]
        self.k0 = float(spec["k0"])
        self.p_ref = float(spec.get("p_ref", 1.0))
        self.eff = spec.get("efficiency")
        self.rho = float(spec["rho"])

    def eta(self, p, b):
        e = self.eff
        if e is None or not e.get("geometric"):
            return None
        return 1.0 / (1.0 + np.exp(-e["bs"] * (b / p - e["cs"])))

    def beta(self, p, q):
        if self.kernel == "constant":
            return self.k0 * np.ones(np.broadcast(p, q).shape)
        if self.kernel == "sum":
            return self.k0 * (p + q)
        u, v = p / self.p_ref, q / self.p_ref
        return self.k0 * (np.cbrt(u) + np.cbrt(v)) ** 2 * np.sqrt(1.0 / u + 1.0 / v)

    def psi(self, p, b, q, c):
        """Success probability of pairs (p, b), (q, c) (arrays broadcast)."""
        e = self.eff
        out = np.ones(np.broadcast(p, q).shape)
        if e is None:
            return out
        y, z = b / p, c / q
        if e.get("geometric"):
            ey = 1.0 / (1.0 + np.exp(-e["bs"] * (y - e["cs"])))
            ez = 1.0 / (1.0 + np.exp(-e["bs"] * (z - e["cs"])))
            out = out * (1.0 - (1.0 - ey) * (1.0 - ez))
        if e.get("physical"):
            d, dd = diameter(p, self.rho), diameter(q, self.rho)
            st = (4.0 * self.rho * e["u0"] * d * dd * (d + dd) ** 2
                  / (9.0 * e["mu"] * (d ** 3 + dd ** 3)))
            lam = e["r_g"] * (np.cbrt(np.exp(e["f"] * (y - e["g"])))
                              + np.cbrt(np.exp(e["f"] * (z - e["g"]))))
            crit = np.where(lam > e["h_a"], 2.0 * np.log(np.maximum(lam, 1e-300) / e["h_a"]),
                            0.0)
            out = out * (st <= crit)
        return out

    def terms(self, p, b):
        """Majorant weights (A, C) of shape (T, n) of granules (p, b)."""
        if self.kernel == "constant":
            a = [0.5 * self.k0 * np.ones(p.shape)]
            c = [np.ones(p.shape)]
        elif self.kernel == "sum":
            a, c = [self.k0 * p], [np.ones(p.shape)]
        else:
            u = p / self.p_ref
            a = [2.0 * self.k0 * u ** (1.0 / 6.0), 2.0 * self.k0 * u ** (2.0 / 3.0)]
            c = [np.ones(p.shape), u ** -0.5]
        eta = self.eta(p, b)
        if eta is not None:
            a = [x * eta for x in a] + a
            c = c + [x * eta for x in c]
        return np.array(a), np.array(c)

    def capture(self, p, b):
        """f beta(p, p_d) psi(granule, droplet) [m3/s] per granule."""
        dr = self.s["droplets"]
        pd = dr["p_d"]
        return dr["factor"] * self.beta(p, pd) * self.psi(p, b, pd, pd)

    def selection(self, p):
        br = self.s.get("breakage")
        if br is None:
            return np.zeros(p.shape)
        return br["s0"] * (p / br["p_ref"]) ** br["exponent"]


def _draw(rng, weights):
    c = np.cumsum(weights)
    return min(int(np.searchsorted(c, rng.random() * c[-1], side="right")), len(weights) - 1)


def _initial(spec, n, rng):
    ini = spec["initial"]
    if ini["distribution"] == "monodisperse":
        p = np.full(n, float(ini["mass"]))
    else:
        p = rng.exponential(float(ini["mean"]), n)
    b = p * float(ini.get("binder_fraction", 0.0))
    return p, b, float(ini["number_density"]) * (
        float(ini["mass"]) if ini["distribution"] == "monodisperse" else float(ini["mean"]))


def simulate(spec, n, seed, times):
    """One replica: a list, per output time [s] (increasing), of (p [kg], b [kg], V [m3],
    n_d [1/m3]) -- the granules' particle list and the box volume.

    ``spec``: rho [kg/m3]; kernel ("constant", "sum", "eke"), k0, p_ref [kg] (eke's reference
    mass); efficiency None or {geometric: bool, physical: bool, bs, cs, f, g, h_a, r_g, u0,
    mu}; droplets None or {p_d [kg], factor, rate [1/(m3 s)], nd0 [1/m3]}; breakage None or
    {s0 [1/s], exponent, p_ref [kg], daughters ("uniform", "equal")}; initial {distribution
    ("monodisperse" with mass [kg], or "exponential" with mean [kg]), number_density [1/m3],
    binder_fraction}."""
    rng = np.random.default_rng(seed)
    ph = _Physics(spec)
    p, b, c0 = _initial(spec, n, rng)
    vol = p.sum() / c0
    dr = spec.get("droplets")
    nd0 = nd = float(dr["nd0"]) if dr else 0.0
    pd_ = float(dr["p_d"]) if dr else 0.0
    rate_inj = float(dr["rate"]) if dr else 0.0
    br = spec.get("breakage")
    A, C = ph.terms(p, b)
    cap = ph.capture(p, b) if dr else np.zeros(n)
    sel = ph.selection(p)
    sums = [A.sum(axis=1), C.sum(axis=1), cap.sum(), sel.sum()]

    def update(idx):
        idx = np.asarray(idx)
        a, c = ph.terms(p[idx], b[idx])
        sums[0] += a.sum(axis=1) - A[:, idx].sum(axis=1)
        sums[1] += c.sum(axis=1) - C[:, idx].sum(axis=1)
        A[:, idx], C[:, idx] = a, c
        if dr:
            k = ph.capture(p[idx], b[idx])
            sums[2] += k.sum() - cap[idx].sum()
            cap[idx] = k
        if br:
            s = ph.selection(p[idx])
            sums[3] += s.sum() - sel[idx].sum()
            sel[idx] = s

    out, t, events = [], 0.0, 0
    times = list(times)
    while times:
        w_terms = sums[0] * sums[1]
        r_agg = w_terms.sum() / vol
        r_cap = max(nd, 0.0) * sums[2]
        r_inj = rate_inj * vol
        r_brk = sums[3]
        total = r_agg + r_cap + r_inj + r_brk
        dt = rng.exponential(1.0 / total) if total > 0 else math.inf
        while times and t + dt >= times[0]:
            out.append((p.copy(), b.copy(), vol, nd))
            times.pop(0)
        if not times:
            break
        t += dt
        events += 1
        if events % RESUM == 0:
            sums[:] = [A.sum(axis=1), C.sum(axis=1), cap.sum(), sel.sum()]
        x = rng.random() * total
        if x < r_agg:
            term = _draw(rng, w_terms)
            i, j = _draw(rng, A[term]), _draw(rng, C[term])
            if i == j:
                continue
            w = A[:, i] @ C[:, j] + A[:, j] @ C[:, i]
            acc = ph.beta(p[i], p[j]) * ph.psi(p[i], b[i], p[j], b[j]) / w
            if rng.random() >= acc:
                continue
            p[i] += p[j]
            b[i] += b[j]
            k = int(rng.integers(n - 1))
            k = k + 1 if k >= j else k              # any granule but slot j
            p[j], b[j] = p[k], b[k]
            update([i, j])
        elif x < r_agg + r_cap:
            i = _draw(rng, cap)
            p[i] += dr["p_d"]
            b[i] += dr["p_d"]
            nd -= 1.0 / vol
            update([i])
        elif x < r_agg + r_cap + r_inj:
            nd += 1.0 / vol
        else:
            i = _draw(rng, sel)
            u = rng.random() if br["daughters"] == "uniform" else 0.5
            second = ((1.0 - u) * p[i], (1.0 - u) * b[i])
            p[i] *= u
            b[i] *= u
            k = int(rng.integers(n + 1))
            changed = [i]
            if k < n:
                p[k], b[k] = second
                changed.append(k)
            update(np.unique(changed))
        vol = p.sum() / (c0 + pd_ * (nd0 + rate_inj * t - nd))
    return out


def percentiles(p, rho, fractions=(0.1, 0.5, 0.9)):
    """Mass-based percentiles [m] of a particle list: the diameter of the first granule, in
    order of mass, at which the cumulative mass reaches each fraction."""
    q = np.sort(p)
    cum = np.cumsum(q) / q.sum()
    idx = np.searchsorted(cum, np.asarray(fractions), side="left")
    return diameter(q[np.minimum(idx, q.size - 1)], rho)


def q3(p, rho, d):
    """Mass fraction [-] of the granules with diameter <= d [m] (array)."""
    q = np.sort(p)
    cum = np.concatenate([[0.0], np.cumsum(q) / q.sum()])
    return cum[np.searchsorted(diameter(q, rho), np.asarray(d), side="right")]


def ensemble(spec, n, replicas, seed, times, grid=None):
    """Replicas with seeds seed, seed + 1, ...: {"percentiles": (mean, half) of shape
    (times, 3) [m], "q3": (mean, half) (times, len(grid)) when a diameter grid [m] is given,
    "moments": (mean, half) of M00, M10, M20 [SI] (times, 3), "n_d": mean (times,)}; half is
    the 95% half-width t_{0.975,R-1} s / sqrt(R)."""
    per, cum, mom, nds = [], [], [], []
    for r in range(replicas):
        snaps = simulate(spec, n, seed + r, times)
        per.append([percentiles(s[0], spec["rho"]) for s in snaps])
        mom.append([[np.sum(s[0] ** k) / s[2] for k in range(3)] for s in snaps])
        nds.append([s[3] for s in snaps])
        if grid is not None:
            cum.append([q3(s[0], spec["rho"], grid) for s in snaps])

    def band(x):
        x = np.asarray(x, dtype=float)
        return x.mean(axis=0), t975(replicas - 1) * x.std(axis=0, ddof=1) / math.sqrt(replicas)

    out = {"percentiles": band(per), "moments": band(mom), "n_d": np.mean(nds, axis=0)}
    if grid is not None:
        out["q3"] = band(cum)
    return out
