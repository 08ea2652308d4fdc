"""Executors: who integrates the per-cell sources of a coupled run.

``run_coupled`` hands its ``CellBatch`` (all active cells), the output times [s] and the
transport operator (or None) to an executor and gets back the history of states, one
(n_cells, n_state) array per output time. ``SerialExecutor`` integrates in this process (numba
threads over the cells); ``pbe_cfd.runs.distributed.ClusterExecutor`` the same on a Dask cluster,
with bitwise the same results. Both have the same methods, so the caller never asks which one
it holds:

run(batch, times, transport, progress)   the history; updates the batch in place
checks_outputs                           True if run() applies ``CellBatch.check_output``
report()                                 what it did (dict), or None
mirror_to_processors(written)            copy written OpenFOAM fields per processor
finish()                                 the output is written: drop what was kept for a resume
close()                                  release the workers
"""
from __future__ import annotations


class SerialExecutor:
    """Integrate every cell in this process."""

    #: run() checks every output time's states (``CellBatch.check_output``) as it goes
    checks_outputs = True

    def run(self, batch, times, transport=None, progress=None) -> list:
        """Advance ``batch`` over the output ``times`` [s]: per interval the sources only, or
        with ``transport`` the operator splitting of transport and sources
        (``Transport.advance``). Raises SimulationError when a cell stops. Returns the states at
        every output time (copies, streamed to disk: ``io.spool.Spool``)."""
        from ..io.spool import Spool
        history = Spool()
        history.append(batch.states)
        for k in range(1, len(times)):
            if transport is None:
                batch.step(times[k - 1], times[k])
            else:
                transport.advance(batch.states, times[k - 1], times[k], batch.source_step)
            batch.check_output(times[k])
            history.append(batch.states)
            if progress is not None:
                progress(times[k] / times[-1], f"t = {times[k]:.4g} s")
        return history

    def report(self):
        """Nothing to report for a serial run."""
        return None

    def mirror_to_processors(self, written, overwrite: bool = False) -> list:
        """No decomposed case: nothing to mirror."""
        return []

    def finish(self):
        """Nothing kept for a resume."""

    def close(self):
        """Nothing to release."""
