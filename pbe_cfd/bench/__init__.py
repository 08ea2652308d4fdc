"""What accuracy costs in time: ``pbe-cfd bench accuracy | throughput | cnmc | laguerre | couple |
integrators | peer | hard-cases``.

accuracy (``accuracy_study``)
    Each method over its accuracy knob -- QMOM nodes 1-4; Laguerre ROM order 2-4 on a coarse
    and a fine grid, moment-consistent and plain; cNMC particles 1e3-1e5 with replicas -- run on
    one well-mixed scene. Relative errors of M00, M20, M11, M02, d43 and the mean binder fraction
    M01/M10 at chosen times against a reference: the analytic solution where the scene has one
    (``analytic_reference``: constant kernel, droplets as ordinary particles), otherwise a cNMC
    ensemble far larger than any tested one, whose own 95% band is reported beside it. Wall time
    is the median of repeated runs; the first call (numba compilation or cache load, Laguerre
    tensor build) is reported apart. Writes accuracy.csv, accuracy.md, pareto.png, accuracy.json.

throughput (``throughput_study``)
    Cell-RHS evaluations per second and cell-steps per second of the shared integrator against
    the number of cells and numba threads, for QMOM N = 2, 3, 4 and the Laguerre ROM m = 2, 3, 4
    (Theta-interpolated tensor) with the ktgf kernel and the geometric and physical efficiency;
    the kernel-only rate (QMOM: the pair-rate evaluations its RHS needs; Laguerre: the bare
    quadratic-form contraction) as the ceiling and each method's share of it; and a plain
    NumPy/SciPy QMOM (``NumpyQMOM``: Wheeler and ``numpy.linalg.eigh`` per call, Python loops)
    integrated per cell by ``scipy.integrate.solve_ivp``, giving the speed-up as a ratio.
    Writes throughput.csv, throughput.md, throughput.png, machine.json.

integrators (``integrator_study``)
    The per-cell integrators explicit, implicit and auto on the seed scene, the ktgf study
    scene and a stiff cell at packing: wall time, RHS calls and error against the explicit
    pair at 100 times tighter tolerance; and the bundled transport scene's solver and
    whole-process time against the same scene without ``[transport]``. Writes
    integrators.csv, integrators.md, integrators.json.

peer (``peer_study``)
    OpenFOAM's own population balance (reactingTwoPhaseEulerFoam's class method) on closed
    one-cell boxes against closed forms or a fine fixed-pivot reference, beside QMOM and the
    cNMC on the same problems; the definition differences in ``peer``'s doc. Writes peer.csv,
    peer.md, peer.png, peer.json.

hard-cases (``hard_cases_study``)
    The hard cell next to packing (docs/results/hard-cases.md) for every method over Theta, the
    gap to packing with and without the friction cap, and the sharp and the smooth Stokes
    switch: whether it finishes, and its difference from the same variant at rtol 1e-10.
    Writes hard-cases.csv, hard-cases.md, hard-cases.json.

cnmc, laguerre, couple
    Seed-scenario cNMC speed per replica (trials and accepted events per second); Laguerre
    tensor build time per order and grid and its RHS rate; cell-steps per second of
    ``run_coupled`` on the bundled small bed and on its cells replicated to ~3600 cells.

Modules: ``common`` (machine, writers), ``analytic`` (closed-form references), ``accuracy``
and ``accuracy_report``, ``integrators``, ``throughput`` with ``sweeps`` (numba) and ``numpy_baseline`` (the
plain NumPy/SciPy QMOM), ``cnmc``, ``laguerre``, ``couple``, ``cluster`` (the Dask path).

Every study accepts ``quick`` (a tiny configuration for tests: well under a minute once numba's
cache is warm). Numbers are measured, never asserted.
"""
from ..runs import model  # noqa: F401 - bench.model: the domain layer the studies build on
from .accuracy import (DEFAULT_ACCURACY_SCENE, QUANTITIES, TIME_FRACTIONS, Variant,
                       accuracy_study, accuracy_variants, chosen_times, cnmc_reference,
                       reference_method, run_variant, table_build_time)
from .accuracy_report import accuracy_markdown, pareto_front, plot_pareto
from .analytic import (analytic_applicable, analytic_moments, analytic_reference,
                       smoluchowski_d43)
from .cluster_3d import cluster_study
from .cnmc import cnmc_study, seed_scenario_benchmark, seed_scenario_setup
from .batch import batch_study
from .common import CNMC_STUDY, LAGUERRE_STUDY, STUDY_FILES, failure_status, machine_info
from .couple import couple_study, replicated_domain
from .hard_cases import hard_cases_study
from .integrators import integrator_markdown, integrator_study, stiff_scene
from . import transport_cost  # noqa: F401 - bench.transport_cost: the baseline check of bench integrators
from .laguerre import laguerre_study
from .numpy_baseline import NumpyQMOM
from .peer import peer_study
from .peer_case import PeerRunError, PeerUnavailable
from .sweeps import (laguerre_contraction_sweep, qmom_kernel_sweep, qmom_node_properties,
                     rhs_sweep)
from .throughput import (DEFAULT_THROUGHPUT_SCENE, ThroughputCase, cell_states,
                         measure_baseline, measure_ceiling, measure_rhs_rate, measure_steps,
                         synthetic_cells, throughput_case, throughput_markdown,
                         throughput_scene, throughput_study, trajectory_states)

#: the studies that write <name>.csv, .md and .json: the function that runs each
SIMPLE_STUDY_RUNS = {CNMC_STUDY: cnmc_study, LAGUERRE_STUDY: laguerre_study,
                     "couple": couple_study, "integrators": integrator_study,
                     "cluster": cluster_study, "batch": batch_study,
                     "hard-cases": hard_cases_study}
