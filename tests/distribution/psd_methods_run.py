"""Run QMOM N = 3, EQMOM N = 3 and the Laguerre ROM on the cases of psd_cases.py and print
their d10, d50, d90 [um] at the end time (python psd_methods_run.py [case ...])."""
import os
import sys
import tomllib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))                    # conftest's make_scene
import psd_cases  # noqa: E402

#: the methods compared: label -> [method] table
METHODS = {"QMOM N=3": {"name": "qmom", "nodes": 3},
           "EQMOM N=3": {"name": "eqmom", "nodes": 3},
           "Laguerre m=3": {"name": "laguerre", "order": 3},
           "Laguerre m=3 following": {"name": "laguerre", "order": 3,
                                      "following_support": True}}


def scene(case, method):
    from pbe_cfd.scene.scene import resolve_scene_path, scene_from_dict
    from conftest import make_scene
    path, tables = psd_cases.scene_tables(case)
    if path is None:
        return make_scene(method=dict(method, _replace=True), **tables)
    src = resolve_scene_path(path)
    data = tomllib.loads(src.read_text())
    if method["name"] == "laguerre":
        lag = tomllib.loads(resolve_scene_path(path + "-laguerre").read_text())["method"]
        data["method"] = dict(lag, **method)
    else:
        data["method"] = dict(method)
    return scene_from_dict(data, str(src))


def run(case, method):
    """The RunResult of the method on the case."""
    from pbe_cfd.runs.simulate import run_well_mixed
    return run_well_mixed(scene(case, method))


def one_gamma(res, rho):
    """d10, d50, d90 [m] at the last output time of the one-kernel gamma fit to the granule
    M00, M10, M20 (the columns less the free droplets, each of mass p_d): QMOM's former
    reconstruction, for comparison."""
    from pbe_cfd.distribution.reconstruct import GammaFit
    c = res.columns
    nd = np.asarray(c.get("droplet_number_density", np.zeros(len(c["time_s"]))))[-1:]
    from pbe_cfd.runs import model
    p_d = float(model.pack(res.scene).droplet_mass) if nd[0] > 0 else 0.0
    m = [np.asarray(c[k])[-1:] - nd * p_d ** i for i, k in enumerate(("M00", "M10", "M20"))]
    return GammaFit(*m, rho).quantiles((0.1, 0.5, 0.9))[0]


def final(res):
    """(d10, d50, d90 [m], psd d [m], Q3 [-]) at the run's last output time."""
    c = res.columns
    t = np.asarray(res.psd["time_s"])
    last = t == t.max()
    return (np.array([c["d10_m"][-1], c["d50_m"][-1], c["d90_m"][-1]]),
            np.asarray(res.psd["d_m"])[last], np.asarray(res.psd["Q3"])[last])


if __name__ == "__main__":
    for case in sys.argv[1:] or psd_cases.CASES:
        for label, method in METHODS.items():
            try:
                res = run(case, method)
            except Exception as exc:            # a stop is a result
                print(case, label, "stops:", str(exc).splitlines()[0][:200], flush=True)
                continue
            q, _, _ = final(res)
            print(case, label, np.round(q * 1e6, 2), "t_end", res.columns["time_s"][-1],
                  res.warnings if hasattr(res, "warnings") else "", flush=True)
