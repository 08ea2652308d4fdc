"""Bivariate Laguerre reduced-order model."""
