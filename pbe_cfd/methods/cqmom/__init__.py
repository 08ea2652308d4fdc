"""Conditional quadrature method of moments for granule mass and binder."""
