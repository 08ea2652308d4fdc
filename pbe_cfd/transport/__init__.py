"""The transport operator between CFD cells and the solids face flux."""
