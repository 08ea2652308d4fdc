"""Closed-form references of the accuracy study: the two-component constant kernel with
injection (moments) and the discrete Smoluchowski equation on a mass lattice (d43)."""
from __future__ import annotations

import math

import numpy as np

from ..runs import model


# ============================================================================ analytic reference
def analytic_applicable(scene) -> bool:
    """True if the scene's moments have the closed form of ``analytic_reference``: a
    well-mixed constant kernel without efficiency factors, droplets (if any) ordinary particles."""
    agg = scene.aggregation
    return (scene.domain.type == "well-mixed" and agg is not None and agg.kernel == "constant"
            and not agg.efficiency and not scene.separate_droplets)


def analytic_moments(scene, times) -> dict:
    """Closed-form moments [SI] of the two-component constant kernel with injection.

    With k0 the kernel [m3/s], R the injection [droplets/(m3 s)] of droplets of mass p_d (pure
    binder, ordinary particles), A = M10(0), C = M01(0), B = R p_d, the moment equations
    (docs/physics.md section 10, the constant kernel's gains 2 p p', p b' + p' b, 2 b b')
        dM00/dt = R - k0 M00^2 / 2,            dM10/dt = dM01/dt = B,
        dM20/dt = k0 M10^2 + R p_d^2,  dM11/dt = k0 M10 M01 + R p_d^2,  dM02/dt = k0 M01^2 + R p_d^2
    close and integrate to
        M00 = N_inf (N0 + N_inf tanh(s t)) / (N_inf + N0 tanh(s t)),  N_inf = sqrt(2 R / k0),
              s = k0 N_inf / 2   (R = 0: M00 = 2 N0 / (2 + k0 N0 t)),
        M10 = A + B t,  M01 = C + B t,
        M20 = M20(0) + R p_d^2 t + k0 (A^2 t + A B t^2 + B^2 t^3 / 3),
        M11 = M11(0) + R p_d^2 t + k0 (A C t + (A + C) B t^2 / 2 + B^2 t^3 / 3),
        M02 = M02(0) + R p_d^2 t + k0 (C^2 t + C B t^2 + B^2 t^3 / 3),
    and the mean binder fraction M01 / M10. Initial moments include free droplets.
    """
    if not analytic_applicable(scene):
        raise ValueError(f"{scene.source}: no closed form (needs a well-mixed constant kernel "
                         "without efficiency and without droplet_factor)")
    t = np.asarray(times, dtype=float)
    k0 = scene.aggregation.rate
    inj = scene.binder_injection
    rate = inj.rate if inj is not None else 0.0
    pd = (model.droplet_mass(inj.droplet_diameter, scene.material.binder_density)
          if inj is not None else 0.0)
    nd0 = scene.initial.droplet_number_density

    def m0(i, j):
        return model.size_moment(scene, i, j) + nd0 * pd ** (i + j)

    n0 = m0(0, 0)
    a_, c_ = m0(1, 0), m0(0, 1)
    b_ = rate * pd
    if rate > 0.0:
        n_inf = math.sqrt(2.0 * rate / k0)
        th = np.tanh(0.5 * k0 * n_inf * t)
        m00 = n_inf * (n0 + n_inf * th) / (n_inf + n0 * th)
    else:
        m00 = 2.0 * n0 / (2.0 + k0 * n0 * t)
    src2 = rate * pd * pd * t
    out = {
        "time_s": t,
        "M00": m00,
        "M10": a_ + b_ * t,
        "M01": c_ + b_ * t,
        "M20": m0(2, 0) + src2 + k0 * (a_ * a_ * t + a_ * b_ * t ** 2 + b_ * b_ * t ** 3 / 3.0),
        "M11": m0(1, 1) + src2 + k0 * (a_ * c_ * t + 0.5 * (a_ + c_) * b_ * t ** 2
                                       + b_ * b_ * t ** 3 / 3.0),
        "M02": m0(0, 2) + src2 + k0 * (c_ * c_ * t + c_ * b_ * t ** 2 + b_ * b_ * t ** 3 / 3.0),
    }
    out["binder_fraction"] = np.where(out["M10"] > 0, out["M01"] / out["M10"], 0.0)
    return out


def _lattice_unit(scene):
    """(unit mass u [kg], granule index q, droplet index r) with p0 = q u and p_d = r u (r = 0
    without droplets), or None if the masses do not share a small lattice."""
    if scene.initial.distribution != "monodisperse":
        return None
    p0 = scene.initial.mean_mass
    inj = scene.binder_injection
    if inj is None:
        return (p0, 1, 0) if scene.initial.droplet_number_density == 0 else None
    pd = model.droplet_mass(inj.droplet_diameter, scene.material.binder_density)
    for r in range(1, 7):
        q = p0 * r / pd
        if round(q) >= 1 and abs(q - round(q)) < 1e-9 * q:
            return pd / r, int(round(q)), r
    return None


def smoluchowski_d43(scene, times, rtol=1e-10):
    """d43 [m] (and the lattice's M00 [1/m3], as a check) of the constant-kernel scene from the
    discrete Smoluchowski equation on the mass lattice n u (granules at n = q, droplets
    entering at n = r; ``_lattice_unit``):
        dc_n/dt = k0/2 sum_{i+j=n} c_i c_j - k0 c_n sum_i c_i + R delta_(n, r),
    truncated at L = 60 x the largest mean size (+64) cells, integrated by DOP853 at rtol 1e-10.
    The mass beyond the lattice is reported (``lost_mass_share``). Returns None if the masses do
    not share a small lattice (then the study has no d43 reference)."""
    from scipy.integrate import solve_ivp

    lat = _lattice_unit(scene)
    if lat is None:
        return None
    unit, q, r = lat
    times = np.asarray(times, dtype=float)
    ana = analytic_moments(scene, times)
    mean_max = float(np.max(ana["M10"] / ana["M00"])) / unit
    size = int(60 * mean_max) + 64
    k0 = scene.aggregation.rate
    inj = scene.binder_injection
    rate = inj.rate if inj is not None else 0.0
    scale = max(float(ana["M00"].max()), 1.0)
    c0 = np.zeros(size + 1)              # index n = 1..size (index 0 unused)
    c0[q] += scene.initial.number_density / scale
    if r > 0:
        c0[r] += scene.initial.droplet_number_density / scale
    kk = k0 * scale

    def rhs(_t, c):
        conv = np.convolve(c, c)[:size + 1]
        dc = 0.5 * kk * conv - kk * c * c.sum()
        if r > 0:
            dc[r] += rate / scale
        return dc

    sol = solve_ivp(rhs, (0.0, float(times[-1])), c0, method="DOP853", t_eval=times,
                    rtol=rtol, atol=1e-14 * c0.max())
    if not sol.success:
        return None
    n = np.arange(size + 1)
    d = np.cbrt(6.0 * n * unit / (math.pi * scene.material.density))
    c = sol.y
    d43 = (d ** 4) @ c / np.maximum((d ** 3) @ c, 1e-300)
    mass = (n * unit) @ c * scale
    lost = float(np.max(np.abs(mass - ana["M10"]) / ana["M10"]))
    d50, step = lattice_median(n, d, c)
    return {"time_s": times, "d43_m": d43, "M00": c.sum(axis=0) * scale, "d50_m": d50,
            "d50_step": step, "lost_mass_share": lost, "lattice_cells": size, "unit_kg": unit}


def lattice_median(n, d, c):
    """Mass median d50 [m] of a lattice distribution at each time: the diameter of the first
    lattice mass n (in increasing order) at which the cumulative mass sum n c_n reaches half
    the total (the particle list's definition, ``methods.cnmc.box``); and per time the
    relative step d(n+1)/d(n) - 1 there (the lattice's resolution of a percentile).
    n (L,) lattice indices, d (L,) their diameters [m], c (L, times) concentrations."""
    mass = n[:, None] * c
    cum = np.cumsum(mass, axis=0)
    k = np.argmax(cum >= 0.5 * cum[-1][None, :], axis=0)
    k1 = np.minimum(k + 1, n.size - 1)
    return d[k], d[k1] / d[k] - 1.0


def analytic_reference(scene, times) -> dict:
    """Reference columns at ``times``: closed-form moments and binder fraction, d43 from the
    discrete Smoluchowski solution where the masses share a lattice. ``info`` says how each
    was obtained and how well the lattice reproduces the closed-form M00."""
    ref = analytic_moments(scene, times)
    info = {"kind": "analytic",
            "text": "closed-form moments of the constant kernel with injection "
                    "(bench.analytic_moments)"}
    lat = smoluchowski_d43(scene, times)
    if lat is not None:
        ref["d43_m"] = lat["d43_m"]
        check = float(np.max(np.abs(lat["M00"] - ref["M00"]) / ref["M00"]))
        info["text"] += (f"; d43 from the discrete Smoluchowski equation on {lat['lattice_cells']}"
                         f" lattice masses (its M00 within {check:.1e} of the closed form, mass "
                         f"beyond the lattice {lat['lost_mass_share']:.1e})")
        info["d43_lattice_m00_check"] = check
        ref["d50_m"] = lat["d50_m"]
        info["d50_lattice_step"] = [float(x) for x in lat["d50_step"]]
        info["text"] += ("; d50 from the same lattice solution (the first lattice mass at "
                         "which the cumulative mass reaches one half, as for a particle list;"
                         " one lattice step there, relative, is listed as its band)")
    else:
        info["text"] += "; no d43 reference (masses not on a common lattice)"
    return ref, info
