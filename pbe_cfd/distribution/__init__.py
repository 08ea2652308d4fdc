"""Granule size distributions from every method's state (docs/physics.md section 11.1).

``reconstruct`` and ``kernel_mixture``: one reconstruction per method (QMOM and CQMOM: N - 1
gamma kernels fitted to the carried size moments; EQMOM: its own kernels; Laguerre ROM: its own
expansion; cNMC: the histogram of its particle lists) exposing the mass-based cumulative Q3(d);
``quantiles``: percentiles and diameter grids of such cumulatives; ``tables``: the
d10/d50/d90/span columns, ``psd.csv`` and the ``columns.json`` sidecar saying which columns are
carried and which reconstructed.
"""
