"""QMOM N = 3, EQMOM N = 3 and the Laguerre ROM with their default reconstructions (gamma
kernels on the granules' support, docs/physics.md section 11.1) against the independent
particle list (tests/references/cnmc_particles.py) on the three cases
of docs/results/psd.md, fixed before any run (psd_cases.py).

Aims (issue 27): d50 within 3%, d10 and d90 within 5% of the reference. A method is within an
aim when its deviation plus the reference's own 95% half-width (relative) is below the aim:
the reference's uncertainty counts against the method. Misses are measured results
(docs/results/psd.md), marked as strict expected failures with their numbers, never tuned.

The reference takes minutes per case (4000 granules x 16 replicas): the tests are ``study``.
"""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import psd_cases  # noqa: E402
import psd_methods_run as M  # noqa: E402
import psd_reference_run  # noqa: E402

AIMS = np.array([0.05, 0.03, 0.05])
#: (case, method) -> the measured miss (docs/results/psd.md)
KNOWN_MISSES = {
    ("sum-a1-uniform", "QMOM N=3"): "d50 -13.1%, d90 +4.29% (+0.75% band): QMOM's M20 is "
                                    "14.8% off here (the closure); the same fit of EQMOM's "
                                    "moments meets the aims (psd_misses.py)",
    ("sum-a1-uniform", "Laguerre m=3"): "d10 +7.9%, d50 +6.3%: the ROM's carried M20 11% "
                                        "high (scene defaults); one gamma of the particle "
                                        "list's own M00..M20 still misses d50 +3.1%",
    ("eke-a1/3-equal", "Laguerre m=3"): "d10 +4.9% (+0.5% band), d50 +5.1%: the ROM's "
                                        "carried M00 4% and M20 6% high (scene defaults); one "
                                        "gamma of the particle list's own M00..M20 misses d50 "
                                        "by +3.6%",
}
#: the methods measured in docs/results/psd.md's percentile table
MEASURED = ("QMOM N=3", "EQMOM N=3", "Laguerre m=3")

_REFERENCE = {}


def reference(case):
    if case not in _REFERENCE:
        _REFERENCE[case] = psd_reference_run.run(case)
    return _REFERENCE[case]


PARAMS = [pytest.param(case, label, marks=[pytest.mark.xfail(
    reason=KNOWN_MISSES[(case, label)], strict=True)] if (case, label) in KNOWN_MISSES else [])
    for case in psd_cases.CASES for label in MEASURED]


@pytest.mark.study
@pytest.mark.parametrize("case,label", PARAMS)
def test_percentiles_within_the_aims_of_the_particle_list(case, label):
    ref = reference(case)
    want = np.array(ref["percentiles"])
    half = np.array(ref["percentiles_half"]) / want
    got, _, _ = M.final(M.run(case, M.METHODS[label]))
    dev = got / want - 1.0
    assert np.all(np.abs(dev) + half <= AIMS), (case, label, np.round(100 * dev, 2))
