"""CQMOM in a coupled run with transport (pbe_cfd.transport.operator) and in its outputs.

A closed ring of 16 cells (tests/transport/test_transport.py) whose circulation (period 0.5 s) is much
faster than aggregation (tens of s): the bed moments must follow a well-mixed CQMOM run whose
ktgf cell factor is the pair-weighted bed average of g0(alpha) sqrt(Theta), within 1% (the
criterion of the QMOM test there: the splitting and the bed averaging of a kernel that varies
by 2x over the ring, not the method, set it), while aggregation changes M00 and M20 by more
than 10%. The transport moves whole states between cells, so the bed's granule mass and
binder mass stay exact (1e-10 relative: round-off over the substeps). The cell fields carry
every M_kl of the state, d32, d43 and the binder fraction M01 / M10 of each active cell.
"""
import numpy as np

from pbe_cfd.runs.couple import run_coupled
from pbe_cfd.physics.kernels import radial_distribution
from pbe_cfd.runs.simulate import run_well_mixed
from pbe_cfd.transport.solids_flux import pair_weighted_average

from conftest import AVICEL, make_scene
from test_transport import P0, RHO, bed_scene, ring

N1, N2 = 2, 2
Y0 = 0.1


def test_cqmom_fast_circulation_approaches_the_bed_averaged_well_mixed_run():
    n = 16
    cells = ring(n=n).cells
    solids = float(np.sum(cells.alpha * cells.cell_volume))
    domain = ring(n=n, flux=solids / 0.5)
    end = 10.0
    agg = {"kernel": "ktgf", "rate": 2.0e-6}
    scene = bed_scene(transport={"split_step": 0.1}, aggregation=agg, end=end, interval=5.0,
                      initial={"binder_fraction": Y0}).with_method(
        name="cqmom", nodes=N1, binder_nodes=N2)
    res = run_coupled(scene, domain)
    on = res.bed_columns
    g0 = np.array([radial_distribution(a, 0.62) for a in cells.alpha])
    factor = pair_weighted_average(g0 * np.sqrt(cells.theta), cells.alpha, cells.cell_volume)
    bed_n = float(np.sum(cells.alpha * cells.cell_volume) / cells.cell_volume.sum()) * RHO / P0
    mixed = run_well_mixed(make_scene(
        scene={"end_time": end, "output_interval": 5.0},
        domain={"type": "well-mixed", "solids_fraction": 0.0,
                "granular_temperature": factor ** 2, "alpha_max": 0.62},
        material=dict(AVICEL),
        initial={"distribution": "monodisperse", "number_density": bed_n, "mean_mass": P0,
                 "binder_fraction": Y0},
        aggregation=agg,
        method={"name": "cqmom", "nodes": N1, "binder_nodes": N2, "_replace": True})).columns
    for name in ("M00", "M20", "M11", "M02"):
        ref = mixed[name][-1]
        assert abs(ref - mixed[name][0]) / ref > 0.1, name      # aggregation really acted
        assert abs(on[name][-1] - ref) / ref < 0.01, (name, on[name][-1], ref)
    for name in ("M10", "M01"):
        assert np.max(np.abs(on[name] / on[name][0] - 1.0)) < 1e-10, name
    assert np.max(np.abs(on["binder_fraction"] - Y0)) < 1e-10
    # every reported field of every active cell
    names = [f"M{k}0" for k in range(2 * N1)] + [f"M{k}{l}" for l in range(1, 2 * N2)
                                                 for k in range(N1)]
    last = res.cell_fields[-1]
    act = last["active"] > 0
    assert act.all()
    for name in names + ["d32", "d43", "binder_fraction"]:
        key = name if name in last else name + "_m"
        assert key in last, (name, sorted(last))
        assert np.all(np.isfinite(last[key][act])) and np.all(last[key][act] >= 0.0), name
    d32 = last["d32" if "d32" in last else "d32_m"][act]
    d43 = last["d43" if "d43" in last else "d43_m"][act]
    d0 = (6 * P0 / (np.pi * RHO)) ** (1 / 3)
    assert np.all(d32 > d0) and np.all(d43 >= d32 * (1 - 1e-12))     # grown, d43 >= d32
    assert np.max(np.abs(last["binder_fraction"][act] - Y0)) < 1e-10
    assert res.stats["transport"]["split_steps"] == round(end / 0.1)
