"""Input and output: OpenFOAM cases, tables, VTK."""
