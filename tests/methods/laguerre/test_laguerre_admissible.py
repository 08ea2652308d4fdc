"""The integrator's admissibility of Laguerre states (``admissible.laguerre_realizable``,
level 0) with round-off floors per total order of the moments.

State (our choice, the magnitudes of the bundled bed's scaled states at 30 min): a wet gamma
population of shape 0.3 in state units with W00 = 2e-4 and W22 = 6e12, b = Y0 p, no dry
class. One floor relative to the largest entry (1e-12 x 6e12 = 6) would accept any W10, W01
or dry D0 above -6, fifteen decades of W00 and six of W10 past their own round-off.
"""
import math

import numpy as np
import pytest

from pbe_cfd.methods.laguerre.admissible import strictly_realizable
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs import model

from test_breakage import Y0
from test_laguerre_following import scene

SHAPE = 0.3
NUMBER = 2.0e-4                      # W00 [state units]
#: theta with W22 = NUMBER theta^4 Gamma(SHAPE + 4) / Gamma(SHAPE) Y0^2 = 6e12
THETA = (6.0e12 / (NUMBER * math.exp(math.lgamma(SHAPE + 4) - math.lgamma(SHAPE))
                   * Y0 ** 2)) ** 0.25


@pytest.fixture(scope="module")
def config():
    cfg = np.asarray(model.pack(scene(True)).config, np.int64)
    assert cfg[P.ORDER] == 3
    return cfg


def bed_state(config):
    m = int(config[P.ORDER])
    s = np.zeros(int(config[P.N_STATE]))
    for i in range(m):
        for j in range(m):
            n = i + j
            s[i * m + j] = (NUMBER * THETA ** n * math.exp(math.lgamma(SHAPE + n)
                                                          - math.lgamma(SHAPE)) * Y0 ** j)
    return s


def test_the_bed_state_is_admissible(config):
    s = bed_state(config)
    assert s[8] == pytest.approx(6.0e12, rel=1e-12, abs=0)
    assert strictly_realizable(s, config, level=0)
    assert strictly_realizable(s, config, level=2)


@pytest.mark.parametrize("entry, value", [
    (3, -1e-3),          # W10 negative: a thousandth of a unit, 1e9 x its own floor
    (1, -1e-3),          # W01
    (9, -1e-3),          # dry D0 (the wet number is 2e-4: a negative dry class of 5x it)
    (10, -1e-3),         # dry D1
])
def test_a_negative_low_moment_is_refused_next_to_large_high_ones(config, entry, value):
    """Red with the former single floor 1e-12 max|state| = 6: these pass it."""
    s = bed_state(config)
    s[entry] = value
    assert not strictly_realizable(s, config, level=0)


@pytest.mark.parametrize("entry, order", [(4, 2), (2, 2), (1, 1)])
def test_round_off_of_its_own_order_is_accepted(config, entry, order):
    """A moment at minus half its order's floor (1e-12 times the largest moment of that total
    order) still passes: the floor is a round-off floor, not zero."""
    s = bed_state(config)
    m = int(config[P.ORDER])
    largest = max(abs(s[i * m + j]) for i in range(m) for j in range(m) if i + j == order)
    s[entry] = -0.5e-12 * largest
    assert strictly_realizable(s, config, level=0)
