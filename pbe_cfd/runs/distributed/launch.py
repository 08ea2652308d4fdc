"""Building the executor of a cluster run from the ``pbe-cfd couple`` options (the CLI hands
them over as plain values)."""
from __future__ import annotations

import os
from pathlib import Path

from ...scene.scene import SceneError
from .cluster import host_cores, start_local_cluster
from .decompose import decompose_case, processor_dirs, read_decomposition
from .executor import ClusterExecutor
from .faults import FAULT_ENV, parse_fault
from .store import ChunkStore, store_path


def resume_manifest(out_dir) -> dict:
    """The manifest of the chunk store of an earlier cluster run whose output directory was
    ``out_dir`` (scene, partition, chunks); SceneError when there is none."""
    manifest = ChunkStore.read_manifest(store_path(out_dir))
    if manifest is None:
        raise SceneError(str(store_path(out_dir)), None,
                         f"--resume {out_dir}: no chunk store {store_path(out_dir)} (made by a "
                         "cluster run with --out DIR and removed after its output was written)")
    return manifest


def check_store(out_dir, overwrite: bool = False):
    """A fresh cluster run writing to ``out_dir``: refuse (exit 2) to discard the chunks an
    earlier run left in ``DIR.chunks/`` unless ``overwrite``; ``--resume`` completes them."""
    store = store_path(out_dir)
    if store.exists() and any(store.iterdir()) and not overwrite:
        raise SceneError(str(store), None, f"holds chunks of an earlier cluster run; "
                         f"`--resume {out_dir}` completes that run, --overwrite starts over "
                         "(only the store's own files are removed)")


def make_executor(scene, domain, out_dir, scene_arg=None, scheduler=None, workers=None,
                  chunks=None, decompose=None, resume=False) -> ClusterExecutor:
    """A ClusterExecutor for a coupled run writing to ``out_dir``: on the Dask scheduler at
    ``scheduler`` or a local cluster of ``workers`` processes (default: one per core),
    ``chunks`` blocks (default 4 per worker, or one per processor directory), after
    ``decompose``-ing the OpenFOAM case into that many subdomains; ``resume`` completes the
    chunks an earlier run left in ``DIR.chunks/``. ``scene_arg`` is recorded for ``--resume``."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise SceneError(scene.source, None, "--workers/--scheduler need dask.distributed: "
                         "pip install \"pbe_cfd[dask]\"") from None
    case_dir, decomposition = None, None
    from ..domain import case_path, is_case_directory
    if is_case_directory(scene):
        case_dir = case_path(scene).resolve()
        if decompose:
            from ...io.openfoam import OpenFOAMError
            if any(case_dir.glob("processor*")):  # decomposePar -force would delete them
                raise SceneError(scene.source, "domain.case", f"--decompose: {case_dir} is "
                                 "already decomposed (processor* directories, which "
                                 "decomposePar -force would delete); drop --decompose to use "
                                 "that decomposition")
            try:
                decompose_case(case_dir, decompose, time=domain.cells.time)
            except OpenFOAMError as exc:
                raise SceneError(scene.source, "domain.case", f"--decompose: {exc}") from None
        if processor_dirs(case_dir):
            decomposition = read_decomposition(case_dir, domain.cells.n_cells)
    elif decompose:
        raise SceneError(scene.source, "domain.case", "--decompose needs an OpenFOAM case "
                         "directory (not a snapshot)")
    fault = parse_fault(os.environ.get(FAULT_ENV))
    if scheduler:
        from distributed import Client
        client, cluster = Client(scheduler), None
    else:
        client, cluster = start_local_cluster(workers or host_cores())
    out = Path(out_dir).resolve()
    if scene_arg and Path(scene_arg).is_file():
        scene_arg = str(Path(scene_arg).resolve())
    return ClusterExecutor(
        client=client, chunks=chunks, decomposition=decomposition,
        store_dir=store_path(out), resume=bool(resume),
        meta={"scene": scene_arg, "out": str(out)}, fault=fault, cluster=cluster,
        case_dir=case_dir)
