"""Quadrature method of moments with node-wise binder."""
