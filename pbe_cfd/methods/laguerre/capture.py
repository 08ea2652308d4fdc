"""Laguerre ROM: the wet gain of granules that take up one droplet, mapped binomially from
their capture moments (docs/physics.md section 9.2 and 15)."""
import numba as nb


@nb.njit(cache=True)
def _binomial(n, k):
    """C(n, k) for small non-negative integers."""
    out = 1.0
    for q in range(k):
        out = out * (n - q) / (q + 1)
    return out


@nb.njit(cache=True, inline="always")
def capture_gain(out, moment, f, m, xd, xl, skip):
    """out[a] += C(i, e1) C(j, e2) xd^(i - e1) xl^(j - e2) moment for every a = (i, j) > f =
    (e1, e2) whose bit is not set in ``skip``: the wet gain [scaled units per s] of granules
    of capture moment ``moment`` (their int k_d p^e1 b^e2 n, scaled) that each take up one
    droplet of scaled mass xd and liquid xl; summed over f it is (p + p_d)^i (b + b_d)^j -
    p^i b^j expanded without cancellation."""
    e1 = f // m
    e2 = f - e1 * m
    for i in range(e1, m):
        ci = _binomial(i, e1) * xd ** (i - e1) * moment
        for j in range(e2, m):
            if (i == e1 and j == e2) or (skip >> (i * m + j)) & 1 == 1:
                continue
            out[i * m + j] += ci * _binomial(j, e2) * xl ** (j - e2)
