"""Runs: the two-way coupled run and its segment store (more runs move here)."""
