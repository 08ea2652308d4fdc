"""Gaussian quadrature from moments shared by the quadrature methods."""
