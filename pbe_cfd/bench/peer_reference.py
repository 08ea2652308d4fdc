"""References of ``pbe-cfd bench peer``: the closed forms of docs/physics.md (constant
aggregation, section 10; constant breakage with uniform daughters, section 8) in volume
moments, and a fine fixed-pivot sectional solver of our own (numpy + scipy) for the problems
without a closed form, extrapolated in its grid spacing.

Volumes x [m3], number densities [1/m3], moments M_k = int x^k n dx [m3^k/m3].
"""
from __future__ import annotations

import math

import numpy as np


# ============================================================================ closed forms
def constant_aggregation_moments(n0, x0, rate, t) -> dict:
    """Monodisperse start (n0 [1/m3] of volume x0 [m3]) under beta = rate [m3/s], 1/2 n n
    convention: M0 = 2 n0 / (2 + rate n0 t), M1 = n0 x0, M2 = n0 x0^2 + rate M1^2 t."""
    m1 = n0 * x0
    return {"M0": 2.0 * n0 / (2.0 + rate * n0 * t), "M1": m1,
            "M2": n0 * x0 * x0 + rate * m1 * m1 * t}


def constant_breakage_moments(n0, x0, rate, t) -> dict:
    """Monodisperse start under S = rate [1/s] with uniform binary daughters:
    M_k = n0 x0^k exp(rate t (2 / (k + 1) - 1))."""
    return {f"M{k}": n0 * x0 ** k * math.exp(rate * t * (2.0 / (k + 1.0) - 1.0))
            for k in (0, 1, 2)}


def linear_breakage_aggregation_m0(n0, x0, rate, t) -> float:
    """M0 [1/m3] under constant aggregation beta = rate [m3/s] and S = x [1/s] (x in m3) with
    uniform binary daughters: dM0/dt = M1 - rate M0^2 / 2 (each break adds one particle at the
    rate int S n = M1, M1 = n0 x0 constant), a Riccati equation with the steady state
    s = sqrt(2 M1 / rate): M0 = s (n0 + s th) / (s + n0 th), th = tanh(rate s t / 2)."""
    m1 = n0 * x0
    s = math.sqrt(2.0 * m1 / rate)
    th = math.tanh(0.5 * rate * s * t)
    return s * (n0 + s * th) / (s + n0 * th)


# ============================================================================ fixed pivot
def geometric_grid(x_low, x_high, per_doubling) -> np.ndarray:
    """Volumes [m3] x_low 2^(i / per_doubling) up to x_high (both included, x_high / x_low a
    power of 2^(1/per_doubling))."""
    n = int(round(per_doubling * math.log2(x_high / x_low)))
    return x_low * 2.0 ** (np.arange(n + 1) / per_doubling)


def _aggregation_matrix(x, rate):
    """Sparse G x G^2 map of the ordered pair products n_i n_j to the birth rates: the pair
    volume v = x_i + x_j shared between the two pivots around it so that number and volume
    are kept (Kumar and Ramkrishna's fixed pivot); pairs beyond the last pivot go to it with
    the volume kept. Each ordered pair carries rate / 2 (the 1/2 n n convention)."""
    from scipy.sparse import csr_matrix
    g = x.size
    v = (x[:, None] + x[None, :]).ravel()
    k = np.clip(np.searchsorted(x, v, side="right") - 1, 0, g - 1)
    top = k >= g - 1
    kk = np.minimum(k, g - 2)
    w_up = np.where(top, 0.0, (v - x[kk]) / (x[kk + 1] - x[kk]))
    w_low = np.where(top, 0.0, 1.0 - w_up)
    w_last = np.where(top, v / x[-1], 0.0)
    cols = np.arange(g * g)
    rows = np.concatenate([kk, kk + 1, np.full(g * g, g - 1)])
    data = 0.5 * rate * np.concatenate([w_low, w_up, w_last])
    return csr_matrix((data, (rows, np.concatenate([cols, cols, cols]))), shape=(g, g * g))


def _uniform_daughter_matrix(x):
    """D[i, k]: daughters of one break of a parent at pivot k landing on pivot i, for the
    uniform binary density 2 / x_k on (0, x_k), shared between neighbouring pivots by the
    linear (number- and volume-keeping) weights; daughters below the first pivot go to it with
    their volume kept (weight v / x_0)."""
    g = x.size
    d = np.zeros((g, g))
    for k in range(1, g):
        b = 2.0 / x[k]
        d[0, k] = b * (0.5 * x[0] + 0.5 * (x[1] - x[0]))
        for i in range(1, k):
            d[i, k] = b * 0.5 * (x[i + 1] - x[i - 1])
        d[k, k] = b * 0.5 * (x[k] - x[k - 1])
    d[0, 0] = 1.0       # a first-pivot parent's daughters all return to it, volume kept
    return d


def fixed_pivot_moments(x, n_start, t_end, aggregation_rate=0.0, breakage_power=None,
                        rtol=1e-10) -> dict:
    """Moments M0, M1, M2 [m3^k/m3] at t_end [s] of the sectional population balance on pivots
    x [m3] from n_start [1/m3]: constant aggregation [m3/s] and breakage S = x^power [1/s]
    (x in m3, None: none) with uniform binary daughters; integrated by DOP853 at ``rtol``.
    Also the volume share on the last pivot ("top_share") and the number of RHS calls."""
    from scipy.integrate import solve_ivp
    g = x.size
    scale = float(n_start.max())
    agg = _aggregation_matrix(x, aggregation_rate * scale) if aggregation_rate > 0 else None
    lin = None
    if breakage_power is not None:
        s = x ** breakage_power
        lin = _uniform_daughter_matrix(x) * s[None, :] - np.diag(s)

    def rhs(_t, n):
        dn = np.zeros(g)
        if agg is not None:
            dn += agg @ np.outer(n, n).ravel() - aggregation_rate * scale * n * n.sum()
        if lin is not None:
            dn += lin @ n
        return dn

    y0 = n_start / scale
    sol = solve_ivp(rhs, (0.0, float(t_end)), y0, method="DOP853", rtol=rtol,
                    atol=1e-14 * float(y0.max()))
    if not sol.success:
        raise RuntimeError(f"fixed-pivot reference failed: {sol.message}")
    n = sol.y[:, -1] * scale
    out = {f"M{k}": float(n @ x ** k) for k in (0, 1, 2)}
    out["top_share"] = float(n[-1] * x[-1] / max(n @ x, 1e-300))
    out["rhs_calls"] = int(sol.nfev)
    return out


def extrapolated_reference(x_low, x_high, x_start, n0, t_end, aggregation_rate=0.0,
                           breakage_power=None, per_doubling=(8, 16)) -> dict:
    """Fixed-pivot moments on two grids (``per_doubling`` pivots per doubling of volume, the
    second twice the first) and their Richardson extrapolation for a second-order error in the
    spacing, M = M_fine + (M_fine - M_coarse) / 3; "spread" is the relative change the
    extrapolation made on each moment (the reference's own uncertainty scale). The population
    starts monodisperse: n0 [1/m3] at the pivot x_start [m3]."""
    runs = []
    for q in per_doubling:
        x = geometric_grid(x_low, x_high, q)
        n = np.zeros(x.size)
        i = int(np.argmin(np.abs(np.log(x / x_start))))
        if abs(x[i] / x_start - 1.0) > 1e-9:
            raise ValueError(f"x_start {x_start} m3 is not a pivot of the reference grid")
        n[i] = n0
        runs.append(fixed_pivot_moments(x, n, t_end, aggregation_rate, breakage_power))
    coarse, fine = runs
    out = {}
    for k in ("M0", "M1", "M2"):
        out[k] = fine[k] + (fine[k] - coarse[k]) / 3.0
        out[f"spread_{k}"] = abs(out[k] - fine[k]) / abs(out[k])
    out["top_share"] = fine["top_share"]
    out["pivots"] = [int(round(q * math.log2(x_high / x_low))) + 1 for q in per_doubling]
    return out
