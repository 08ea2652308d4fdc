"""The 3-D bed generator (``pbe-cfd case make --3d``): the cell count asked for, a face flux
divergence-free on every cell to round-off with granules crossing the depth, the small
case's fields at every depth, and a snapshot that ``couple`` reads."""
import math

import numpy as np
import pytest

from pbe_cfd.cli import main
from pbe_cfd.io.openfoam import load_snapshot
from pbe_cfd.io.openfoam.bed3d import FLUX_NAME, VTU_NAME, grid_for, make_bed


@pytest.mark.parametrize("n", [1000, 20_000, 1_000_000])
def test_grid_has_about_the_cells_asked(n):
    nx, ny, nz = grid_for(n)
    # each of the three counts is rounded by at most half a cell
    bound = sum(0.5 / m for m in (nx, ny, nz)) * 1.05
    assert abs(nx * ny * nz / n - 1.0) < bound + 0.5 * bound ** 2


def test_flux_is_divergence_free_and_three_dimensional():
    points, hexes, fields, flux, meta = make_bed(3000)
    nx, ny, nz = meta["grid"]
    assert flux.n_cells == nx * ny * nz == hexes.shape[0]
    scale = np.abs(flux.flux).max()
    # each net outflow sums at most 6 face fluxes of size <= scale: round-off 6 eps scale
    assert np.abs(flux.net_outflow()).max() <= 6 * np.finfo(float).eps * scale * 4
    centre = fields["cell_centre"]
    dz = np.abs(centre[flux.neighbour, 2] - centre[flux.owner, 2]) > 1e-12
    assert np.abs(flux.flux[dz]).sum() > 0.05 * np.abs(flux.flux).sum()   # depth-wise
    # cells ordered x fastest, then y, then z, as one blockMesh block numbers them
    assert np.all(np.diff(centre[:nx, 0]) > 0) and centre[nx, 1] > centre[0, 1]


def test_fields_are_the_small_case_at_every_depth():
    _, _, fields, _, meta = make_bed(3000)
    nx, ny, nz = meta["grid"]
    alpha = fields["alpha"].reshape(nz, ny, nx)
    assert np.array_equal(alpha, np.broadcast_to(alpha[0], alpha.shape))
    small = load_snapshot()
    # solids volume per unit bed volume: the same bed, within the interpolation's error
    # (bilinear between 15 x 60 centres: the mean of a smooth field moves by O(h^2))
    mean_small = float(np.sum(small.alpha * small.cell_volume) / np.sum(small.cell_volume))
    assert math.isclose(float(alpha.mean()), mean_small, rel_tol=0.05, abs_tol=0.0)


def test_case_make_writes_a_snapshot_couple_reads(tmp_path):
    out = tmp_path / "bed"
    assert main(["case", "make", "--3d", "--cells", "2000", "--dir", str(out)]) == 0
    cells, flux = load_snapshot(out / VTU_NAME, with_flux=True)
    assert (out / FLUX_NAME).is_file()
    assert cells.n_cells == flux.n_cells == int(np.prod(grid_for(2000)))
    assert np.all(cells.cell_volume > 0)
    # a second make into the same directory needs --overwrite; other files are refused
    assert main(["case", "make", "--3d", "--cells", "2000", "--dir", str(out)]) == 2
    assert main(["case", "make", "--3d", "--cells", "2000", "--dir", str(out),
                 "--overwrite"]) == 0
    assert main(["case", "make", "--cells", "2000", "--dir", str(tmp_path / "x")]) == 2
