"""``pbe-cfd compile``: compile the kernels of scenes into numba's cache ahead of their runs.

A scene's run compiles its integration kernel (its method and integrator, plus the
transport's repair with ``[transport]``) on its first use on a machine. ``compile_scene`` builds
the same packed problem the run builds and compiles (or loads) the same kernels, on no cells;
the cache it fills (``pbe_cfd.util.kernel_cache``) then serves every later run of the same
sources, wherever they are installed.
"""
from __future__ import annotations

import sys
import time as _time


def compile_scene(scene, progress=None) -> dict:
    """Compile (or load from the cache) the kernels a run of ``scene`` uses. ``progress``
    (an object with ``notice(text)``, or None) is told what compiles and roughly how long
    when it takes long. Returns {"kernel": name, "seconds": wall time [s], "cpu_s": CPU
    time [s], "compiled": True if numba compiled (False: loaded from the cache)}; for a
    method that integrates no ODE (cNMC), {"kernel": None, ...} with nothing compiled."""
    from .batch import CellBatch, check_physics
    from .problem import problem_of
    from ..methods.registry import method_of
    check_physics(scene)
    if not method_of(scene).integrated:
        return {"kernel": None, "seconds": 0.0, "cpu_s": 0.0, "compiled": False}
    domain = None
    if scene.domain.type == "openfoam":
        from .domain import load_domain
        domain = load_domain(scene, need_flux=scene.transport is not None)
    problem = problem_of(scene, domain)
    batch = CellBatch.for_problem(problem)
    extra = None
    if scene.transport is not None and domain is not None:
        from ..transport.operator import build_transport
        transport = build_transport(scene, domain, problem.active, problem.mesh_rows,
                                    arrays=problem.arrays, aux=problem.aux)
        extra = lambda: transport.compile(batch.states.shape[1])  # noqa: E731
    cpu = _time.process_time()
    seconds = batch.compile_announced(progress, extra)
    return {"kernel": batch.kernel_name(), "seconds": seconds,
            "cpu_s": _time.process_time() - cpu, "compiled": batch.compiled_now}


class _Lines:
    """Progress of ``pbe-cfd compile``: each notice a line on stderr."""

    def __init__(self, label):
        self.label = label

    def notice(self, text):
        print(f"{self.label}: {text}", file=sys.stderr, flush=True)


def compile_command(args) -> int:
    """``pbe-cfd compile [SCENE ...]``: compile the kernels of the scenes (default: those of
    the README's first run, ``args.defaults``) and say for each what was compiled and how
    long it took [s]."""
    import pbe_cfd
    from ..scene.scene import load_scene
    from ..util.kernel_cache import cache_root

    names = args.scenes or list(args.defaults)
    scenes = [load_scene(name) for name in names]          # every scene read before any work
    total = 0.0
    for scene in scenes:
        done = compile_scene(scene, _Lines(scene.name))
        total += done["seconds"]
        if done["kernel"] is None:
            print(f"{scene.name}: {scene.method.name} integrates no ODE: nothing to compile "
                  "ahead")
        elif done["compiled"]:
            print(f"{scene.name}: compiled {done['kernel']} in {done['seconds']:.1f} s "
                  f"({done['cpu_s']:.1f} s CPU)")
        else:
            print(f"{scene.name}: {done['kernel']} was compiled already (loaded in "
                  f"{done['seconds']:.2f} s)")
    print(f"kernels in {cache_root(pbe_cfd._source_hash())} ({total:.1f} s)")
    return 0


def add_compile_parser(sub, defaults):
    """The ``compile`` verb of the command line; ``defaults``: the scenes compiled when none
    is named."""
    p = sub.add_parser("compile", help="compile the kernels of scenes ahead of their first "
                       f"run (default: {', '.join(defaults)})")
    p.add_argument("scenes", nargs="*", metavar="SCENE",
                   help="scene TOML files or bundled scene names")
    p.set_defaults(func=compile_command, defaults=tuple(defaults))
