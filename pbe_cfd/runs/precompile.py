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


def _prepared(scene):
    """(the scene's packed problem, its CellBatch, a function compiling the transport's
    kernels or None), or (None, None, None) for a method that integrates no ODE (cNMC)."""
    from .batch import CellBatch, check_physics
    from .problem import problem_of
    from ..methods.registry import method_of
    check_physics(scene)
    if not method_of(scene).integrated:
        return None, None, None
    domain = None
    if scene.domain.type == "openfoam":
        from .domain import load_domain
        domain = load_domain(scene, need_flux=scene.transport is not None)
    problem = problem_of(scene, domain)
    batch = CellBatch.for_problem(problem)
    extra = None
    if problem.transport is not None and domain is not None:
        from ..transport.operator import build_transport
        transport = build_transport(problem.transport, domain, problem.active,
                                    problem.mesh_rows, arrays=problem.arrays, aux=problem.aux)
        extra = lambda: transport.compile(batch.states.shape[1])  # noqa: E731
    return problem, batch, extra


def _stages_of(batch):
    """The compile stages of the batch's kernel (``integrate.warmup.warm_stages``)."""
    from ..integrate.warmup import warm_stages
    from ..physics import parameters as P
    return warm_stages(int(batch.config[P.METHOD]), int(batch.config[P.INTEGRATOR]),
                       batch.aux, batch.params, batch.config)


def _group_task(scene_name, stage, group):
    """In a helper process: compile group ``group`` of stage ``stage`` of the scene's kernel
    into numba's disk cache; the last group of the last stage (the integrator's, the lighter)
    also compiles the output assembly's functions (``simulate.warm_outputs``). Returns (names
    compiled, CPU seconds)."""
    from ..integrate.warmup import compile_group
    from ..scene.scene import load_scene
    from .simulate import warm_outputs
    cpu = _time.process_time()
    scene = load_scene(scene_name)
    problem, batch, _extra = _prepared(scene)
    stages = _stages_of(batch)
    done = compile_group(stages[stage][group])
    if stage == len(stages) - 1 and group == len(stages[stage]) - 1:
        warm_outputs(problem, scene)
    return done, _time.process_time() - cpu


def _warm_in_parallel(scene_name, batch, jobs, say) -> dict:
    """Compile the stages of the scene's kernel (``integrate.warmup``) in ``jobs`` helper
    processes, stage after stage. Returns {"stages": the stages, "cpu_s": the helpers' CPU
    seconds, "compiled": names the helpers compiled}."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    stages = _stages_of(batch)
    cpu, names = 0.0, []
    with ProcessPoolExecutor(max_workers=jobs,
                             mp_context=multiprocessing.get_context("spawn")) as pool:
        for k, stage in enumerate(stages):
            say(f"stage {k + 1} of {len(stages) + 1}: "
                + "; ".join(", ".join(name for name, _d, _s in group) for group in stage))
            start = _time.perf_counter()
            futures = [pool.submit(_group_task, scene_name, k, g) for g in range(len(stage))]
            spent = []
            for future in futures:
                done, seconds = future.result()
                names += done
                cpu += seconds
                spent.append(f"{seconds:.1f}")
            say(f"stage {k + 1} done in {_time.perf_counter() - start:.1f} s "
                f"({' + '.join(spent)} s CPU)")
    return {"stages": stages, "cpu_s": cpu, "compiled": sorted(set(names))}


def compile_scene(scene, progress=None, jobs=1, scene_name=None) -> dict:
    """Compile (or load from the cache) the kernels a run of ``scene`` uses, and the numba
    functions of its output assembly (``simulate.warm_outputs``). ``progress``
    (an object with ``notice(text)``, or None) is told what compiles and roughly how long
    when it takes long. With ``jobs`` > 1 and ``scene_name`` (what ``load_scene`` reads the
    scene from, for the helper processes), the kernel and the method's functions compile in
    ``jobs`` processes, stage by stage (``integrate.warmup``), unless they are in the cache
    already, and this process loads them. Returns {"kernel": name, "seconds": wall time
    [s], "cpu_s": CPU time [s] of this process and the helpers, "compiled": True if numba
    compiled (False: loaded from the cache), "helpers": the helpers' compile or None,
    "recompiled": staged functions compiled again here}; for a method that integrates no
    ODE (cNMC), {"kernel": None, ...} with nothing compiled."""
    problem, batch, extra = _prepared(scene)
    if batch is None:
        return {"kernel": None, "seconds": 0.0, "cpu_s": 0.0, "compiled": False,
                "helpers": None, "recompiled": []}
    from .. import integrate
    from ..integrate.warmup import cache_misses, recompiled
    start, cpu = _time.perf_counter(), _time.process_time()
    helpers = None
    if jobs > 1 and scene_name is not None and not integrate.kernel_ready(
            batch.aux, batch.params, batch.config):
        say = progress.notice if progress is not None else (lambda text: None)
        from ..util.progress import compile_text
        say(f"{compile_text(batch.kernel_name())}; in {jobs} processes, stage by stage, "
            "then loaded here")
        try:
            helpers = _warm_in_parallel(scene_name, batch, jobs, say)
        except Exception as exc:       # a helper that fails costs its share, not the compile
            say(f"the helper processes failed ({type(exc).__name__}: {exc}); compiling "
                "everything here")
    before = cache_misses(helpers["stages"]) if helpers else {}
    batch.compile_announced(progress, extra)
    again = recompiled(helpers["stages"], before) if helpers else []
    if helpers:                        # a helper warmed the outputs' functions too
        from ..util.progress import record_compile_s
        record_compile_s(batch.kernel_name(), _time.process_time() - cpu + helpers["cpu_s"])
    else:
        from .simulate import warm_outputs
        warm_outputs(problem, scene)
    return {"kernel": batch.kernel_name(), "seconds": _time.perf_counter() - start,
            "cpu_s": _time.process_time() - cpu + (helpers["cpu_s"] if helpers else 0.0),
            "compiled": batch.compiled_now or bool(helpers and helpers["compiled"]),
            "helpers": helpers, "recompiled": again}


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
    for name, scene in zip(names, scenes):
        done = compile_scene(scene, _Lines(scene.name), jobs=args.jobs, scene_name=name)
        total += done["seconds"]
        if done["kernel"] is None:
            print(f"{scene.name}: {scene.method.name} integrates no ODE: nothing to compile "
                  "ahead")
        elif done["compiled"]:
            helpers = done["helpers"]
            where = (f", {len(helpers['compiled'])} functions of it in {args.jobs} processes "
                     f"({helpers['cpu_s']:.1f} s CPU there)" if helpers else "")
            print(f"{scene.name}: compiled {done['kernel']} in {done['seconds']:.1f} s "
                  f"({done['cpu_s']:.1f} s CPU{where})")
            if done["recompiled"]:
                print(f"{scene.name}: compiled again for the kernel (their staged argument "
                      f"types did not match): {', '.join(done['recompiled'])}")
        else:
            print(f"{scene.name}: {done['kernel']} was compiled already (loaded in "
                  f"{done['seconds']:.2f} s)")
    print(f"kernels in {cache_root(pbe_cfd._source_hash())} ({total:.1f} s)")
    return 0


def _default_jobs() -> int:
    import os
    return max(1, min(2, os.cpu_count() or 1))


def _jobs(text) -> int:
    import argparse
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"--jobs: expected a whole number >= 1, got {text!r}")
    return value


def add_compile_parser(sub, defaults):
    """The ``compile`` verb of the command line; ``defaults``: the scenes compiled when none
    is named."""
    p = sub.add_parser("compile", help="compile the kernels of scenes ahead of their first "
                       f"run (default: {', '.join(defaults)})")
    p.add_argument("scenes", nargs="*", metavar="SCENE",
                   help="scene TOML files or bundled scene names")
    p.add_argument("-j", "--jobs", type=_jobs, default=_default_jobs(),
                   help="processes that compile a kernel and its method's functions in "
                        f"parallel (default: {_default_jobs()}, the cores up to 2; 1: all in "
                        "this one)")
    p.set_defaults(func=compile_command, defaults=tuple(defaults))
