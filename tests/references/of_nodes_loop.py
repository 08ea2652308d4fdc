"""The gamma fit of quadrature populations row by row, as plain Python loops (the reference
for ``distribution.kernel_mixture.of_nodes``'s fit of all rows at once; imports nothing from
pbe_cfd). Per row: a node not finite -> no kernel (FAILED); the distinct valid nodes (w > 0,
p > 0, equal masses merged); with a floor s > 0 and two or more nodes, relative variance at
most ``delta_rel_var`` -> a delta at the mean, a mean not above s -> the floor dropped; at most
one node -> a delta; two nodes -> one gamma kernel in closed form, u2 = M20 M00 / M10^2 of
p - s: u2 < 1 a delta (flagged), |(u2 - 1) / u2| <= ``root_tolerance`` discrete, else sigma
= (u2 - 1) mean; more nodes -> ``fit_row(x, w, n)``, supplied by the caller.

Status codes are passed in (``codes``: FIT, DISCRETE, FAILED) so that nothing is shared."""
import numpy as np


def _distinct(w, p):
    ok = (w > 0) & (p > 0)
    masses = sorted(set(p[ok].tolist()))
    weights = [float(sum(wi for wi, pi in zip(w[ok], p[ok]) if pi == m)) for m in masses]
    return np.array(masses), np.array(weights)


def fit_rows(w_rows, p_rows, floor, delta_rel_var, root_tolerance, codes, fit_row):
    """[(sigma [kg], centres [kg] above the row's floor, weights [1/m3], status)] per row, the
    rows' floors [kg] and {"delta", "bad", "below", "one"}: the flagged rows."""
    fit, discrete, failed = codes
    out, floors, flags = [], [], {"delta": [], "bad": [], "below": [], "one": []}
    for r, (w, p) in enumerate(zip(w_rows, p_rows)):
        w, p = np.asarray(w, float), np.asarray(p, float)
        s = float(floor)
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(p))):
            out.append((0.0, np.zeros(0), np.zeros(0), failed))
            flags["bad"].append(r)
            floors.append(s)
            continue
        x, wx = _distinct(w, p)
        m0 = float(wx.sum())
        mean = float((wx * x).sum() / m0) if m0 > 0 else 0.0
        if s > 0 and x.size > 1:
            if float((wx * (x - mean) ** 2).sum() / m0) <= delta_rel_var * mean * mean:
                x, wx = np.array([mean]), np.array([m0])
            elif not mean > s:
                s = 0.0
                flags["below"].append(r)
        floors.append(s)
        if x.size <= 1:
            out.append((0.0, x - s, wx, discrete))
        elif x.size == 2 and x[0] > s:
            u = x - s
            mu = float((wx * u).sum() / m0)
            u2 = float((wx * (u / mu) ** 2).sum() / m0)
            f0 = (u2 - 1.0) / u2
            if f0 < 0.0:
                out.append((0.0, np.array([mu]), np.array([m0]), discrete))
                flags["delta"].append(r)
            elif abs(f0) <= root_tolerance:
                out.append((0.0, np.array([mu]), np.array([m0]), discrete))
            else:
                out.append(((u2 - 1.0) * mu, np.array([mu]), np.array([m0]), fit))
        else:
            sigma, c, cw, status = fit_row(x - s, wx, x.size - 1)
            if status == failed:
                sigma, c, cw, status = fit_row(x - s, wx, 1)
                flags["one"].append(r)
            if status == failed:
                sigma, c, cw, status = 0.0, np.array([mean - s]), np.array([m0]), discrete
                flags["delta"].append(r)
            out.append((sigma, c, cw, status))
    return out, floors, flags
