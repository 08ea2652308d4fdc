"""Constant-number Monte Carlo reference."""
