"""Result files, their manifest and guard, OpenFOAM case I/O, VTK series."""
