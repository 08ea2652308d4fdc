"""The output-time guard of the Laguerre ROM: the carried moments of every cell must be those
of a positive population, and the reconstruction's d43 positive.

The integrator accepts a step on the level-0 sign checks of ``admissible`` (stricter levels
stall it on exact delta starts), and a signed reconstruction can give a negative M_(4/3), so
without this guard a cell whose moments left the realizable set would be written as numbers.
``unrealizable_row`` finds the first row of scaled states (one per cell) that fails; the run
stops there with ``realizability_text`` (exit 1, nothing written).

Conditions, per class (wet W_ij, dry D_k; a class counts as present if its number or mass
exceeds 1e-12 of both classes' number or mass): the number and mass M00 > 0 and
M10 > 0; binder mass M01 >= 0 (the wet class only); for m >= 3 the Hankel (Cauchy-Schwarz)
conditions M20 M00 >= M10^2 and M02 M00 >= M01^2 (a non-negative variance in p and in b),
with relative slack HANKEL_SLACK; and for the whole granule population the reconstruction's
M_(4/3) > 0, the numerator of d43.
"""
import math

import numpy as np

from .layout import (AUX_NSLICE, AUX_OFF_F43, AUX_OFF_F43D, AUX_ORDER, carried_shape,
                     weight_corners,
                     wet_support)

#: relative slack of the Hankel conditions [-], ours: a class that starts on the equality (a
#: monodisperse start; every granule with the same binder fraction, b = y p) is pushed out
#: of it by the closure and the integration error -- measured M20 M00 / M10^2 = 0.999815 for
#: the dry class of the m = 4 seed scenario from a dry start at 60 s (its moments within the
#: seed's accuracy of the cNMC), and 1 - 1e-6 after 1e-3 s of aggregation + breakage at
#: rtol 1e-8 -- so only a variance below -1e-2 mean^2 (an imaginary spread of 10% of the
#: mean, 50x the largest measured) stops the run
HANKEL_SLACK = 1e-2
#: round-off floor of a state, relative to its largest entry [-]
ROUND_OFF = 1e-12


def reconstructed_m43(state, aux):
    """M_(4/3) of a scaled state's reconstruction (wet and dry classes) [per N_ref, in
    p_ref^(4/3)]: the tabulated functionals F43 (blended over the weight slices as the RHS
    blends them) and F43D applied to the carried moments, unbounded (the quantity whose
    sign decides the sign of the output d43)."""
    m = int(aux[AUX_ORDER])
    K = m * m
    s = np.asarray(state, float)
    total = 0.0
    for w, frac in weight_corners(s, aux):
        o = int(aux[AUX_OFF_F43]) + w * K
        total += frac * float(np.dot(aux[o:o + K], s[:K]))
    od = int(aux[AUX_OFF_F43D])
    return total + float(np.dot(aux[od:od + m], s[K:K + m]))


def aggregation_number_rates(state, aux):
    """The granule number's aggregation rate d(W00 + D0)/dt of a scaled state's reconstruction
    at every collision-velocity slice of the tables, per unit kernel multiplier (the cell
    factor k0 N_ref F_cell > 0 only scales it) [1/s in scaled units, one value per slice]:
    the wet, dry and dry-wet quadratic forms of the RHS, blended over the weight slices as
    the RHS blends them, without capture (which moves no granule number) or breakage. For
    any positive population every value is <= 0 (-1/2 of the double integral of beta n n
    with beta >= 0); a positive value means the signed reconstruction, as the kernel sees
    it, is not a population (docs/results/laguerre.md, the bed batch's M00)."""
    from .position import _weight_position, binder_shift, scale_binder
    from .rhs import _aggregation_and_capture, _any_nonzero
    m = int(aux[AUX_ORDER])
    K = m * m
    s = np.ascontiguousarray(state, dtype=float)
    wet, dry = _any_nonzero(s, 0, K), _any_nonzero(s, K, K + m)
    shift = binder_shift(s, aux, m) if wet else 0.0
    if shift != 0.0:                # as the RHS: the number rate is that of the scaled state
        scaled = np.empty_like(s)
        scale_binder(s, scaled, aux, m, s.size, shift)
        s = scaled
    wpos = _weight_position(s, aux, m)
    out = np.zeros(s.size)
    rates = []
    for sl in range(max(1, int(aux[AUX_NSLICE]))):
        out[:] = 0.0
        if wet or dry:
            _aggregation_and_capture(s, out, aux, m, 1.0, 0.0, wet, dry, wpos, sl, 0.0, 0.0,
                                     0.0)
        rates.append(out[0] + out[K])
    return np.array(rates)


def _class_failure(M, m, floor0, floor1, wet):
    """(moment condition, value text) a class's moments M(i, j) break, or None; floor0,
    floor1: the round-off floors of its number and mass (those of both classes together)."""
    if not (abs(M(0, 0)) > floor0 or abs(M(1, 0)) > floor1):
        return None                                   # the class is empty
    if not M(0, 0) > 0.0:
        return "M00 > 0", f"M00 = {M(0, 0):.4g}"
    if not M(1, 0) > 0.0:
        return "M10 > 0", f"M10 = {M(1, 0):.4g}"
    if wet and M(0, 1) < -floor1:
        return "M01 >= 0", f"M01 = {M(0, 1):.4g}"
    if m < 3:
        return None
    checks = [("M20 M00 >= M10^2", M(2, 0) * M(0, 0), M(1, 0) ** 2, "M20 M00 / M10^2")]
    if wet and M(0, 1) != 0.0:
        checks.append(("M02 M00 >= M01^2", M(0, 2) * M(0, 0), M(0, 1) ** 2, "M02 M00 / M01^2"))
    for name, big, small, ratio in checks:
        if not big >= small * (1.0 - HANKEL_SLACK):
            return name, f"{ratio} = {big / small:.6g}"
    return None


def state_failure(state, aux, number_scale=1.0, mass_scale=1.0):
    """(condition, value text) of the first realizability condition a scaled state breaks,
    or None (module doc); number_scale [1/m3] and mass_scale [kg] (N_ref, p_ref) put the
    reconstruction's M_(4/3) of the text in kg^(4/3)/m3."""
    m = int(aux[AUX_ORDER])
    K = m * m
    s = np.asarray(state, float)
    if not np.all(np.isfinite(s)):
        return "finite moments", "a carried moment is not finite"
    # round-off floors per moment (the entries span many decades: W22 can exceed W00 by
    # 1e16, so a floor relative to the largest entry would accept any sign of M00, M10)
    floor0 = ROUND_OFF * abs(s[0] + s[K])
    floor1 = ROUND_OFF * abs(s[m] + s[K + 1])
    for label, M, wet in (("wet class", lambda i, j: s[i * m + j], True),
                          ("dry class", lambda i, j: s[K + i] if j == 0 else 0.0, False)):
        found = _class_failure(M, m, floor0, floor1, wet)
        if found is not None:
            return f"{found[0]} ({label})", found[1]
    if s[m] + s[K + 1] > 0.0:
        m43 = reconstructed_m43(s, aux)
        if not m43 > 0.0:
            si = m43 * number_scale * mass_scale ** (4.0 / 3.0)
            return ("d43 > 0", f"the reconstruction's M_(4/3) = {si:.4g} kg^(4/3)/m3, the "
                    "numerator of d43")
    return None


def unrealizable_row(states, aux, number_scale=1.0, mass_scale=1.0):
    """(row, condition, value text) of the first row of scaled states (one per cell) that
    breaks a realizability condition, or None (scales: ``state_failure``)."""
    for r, state in enumerate(np.atleast_2d(states)):
        found = state_failure(state, aux, number_scale, mass_scale)
        if found is not None:
            return (r,) + found
    return None


def weight_text(state, aux, mass_scale):
    """The wet class's carried weight parameters and its support, for a message: the
    mass-weighted mean mass c_m = W20 / W10 [kg], the carried gamma shape, the binder
    fraction W01 / W10 and the blended slices' largest support p_max [kg]."""
    m = int(aux[AUX_ORDER])
    s = np.asarray(state, float)
    parts = []
    if m >= 3 and s[m] != 0.0:
        parts.append(f"c_m = W20/W10 = {s[2 * m] / s[m] * mass_scale:.4g} kg")
        var = s[0] * s[2 * m] - s[m] * s[m]
        parts.append(f"carried shape {carried_shape(s[0], s[m], s[2 * m]):.4g}" if var > 0.0
                     else "no positive variance in p")
    if s[m] != 0.0:
        parts.append(f"binder fraction {s[1] / s[m]:.4g}")
    corners = weight_corners(s, aux)
    p_top = max(wet_support(aux, w)[0] for w, _ in corners)
    parts.append(f"weight slices {sorted(w for w, _ in corners)} with support p_max = "
                 f"{p_top:.4g} kg")
    return ", ".join(parts)


def output_check(states, aux, arrays):
    """(row, text) of the first cell whose carried moments are not realizable, or None:
    the method's output-time guard (``MethodEntry.output_check``)."""
    found = unrealizable_row(states, aux, arrays.number_scale, arrays.mass_scale)
    if found is None:
        return None
    r, condition, value = found
    state = np.atleast_2d(states)[r]
    what = ("the reconstruction of its carried moments on the weight slices gives no positive "
            "d43" if condition == "d43 > 0" else "its carried moments are not those of a "
            "positive population")
    return r, (f"the Laguerre ROM broke {condition}: {value} (wet class: "
               f"{weight_text(state, aux, arrays.mass_scale)}); {what}, so nothing is "
               f"written{_support_hint(state, aux, arrays)}")


def _support_hint(state, aux, arrays):
    """The escape report's text where mass has left the support (its share and the [method]
    key to change), else the advice to use qmom."""
    from .tensor import ESCAPE_WARN_SHARE, escaped_share_report, failure_hint
    share, _ = escaped_share_report(np.atleast_2d(state), aux, arrays)
    return failure_hint(state, aux, arrays) if share > ESCAPE_WARN_SHARE else "; use qmom"
