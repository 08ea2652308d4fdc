"""OpenFOAM case I/O of the coupled runs."""
