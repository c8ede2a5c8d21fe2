"""Slits in the pixel equation: the stencil links that cross a slit carry no flux, in every pixel
operator (residual and check, exact solver, correction), and the certificate still holds."""

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg
from conftest import assert_certificate_bounds_the_error

from ifenn.pixel_equation.numpy_backend import PixelEquation, laplacian_matrix, normalised_residual, solve_pixel_equation
from ifenn.pixels import PixelGrid, SlitCuts

GC, LC = 2.7, 0.15
SCENE = {"domain": {"x": [-0.5, 0.5], "y": [-0.5, 0.5]}, "elements": [20, 20],
         "notches": [{"kind": "slit", "start": [-0.5, 0.0], "end": [-0.2, 0.0]}]}


def _setup(scene=SCENE, padding="replicate"):
    grid = PixelGrid.for_scene(scene)
    return grid, SlitCuts.for_scene(scene, grid, padding)


def _history(grid, seed=0, centre=(-0.2, 0.0), shear=True):
    """A smooth history peak at the slit's tip; with ``shear`` larger above the slit than below
    (what a shear load gives), else mirror-symmetric about it (mode I)."""
    x, y = grid.pixel_centres()
    xx, yy = np.meshgrid(x, y)
    peak = 2e3 * np.exp(-((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2) / 0.02)
    if shear:
        peak *= np.where(yy > 0, 1.0, 0.2)
    noise = 1.0 + 0.05 * np.random.default_rng(seed).random(grid.shape)
    return peak * noise


def test_cuts_are_the_links_across_the_slit_and_symmetric():
    grid, cuts = _setup()
    ny, nx = grid.shape  # 40 x 40, the slit on the row boundary 19 | 20, columns 0..11
    rows, cols = np.divmod(cuts.rows, nx), np.divmod(cuts.cols, nx)
    assert set(rows[0]) | set(cols[0]) == {19, 20} and (rows[0] != cols[0]).all()
    assert rows[1].max() <= 11 and rows[1].min() == 0
    matrix = cuts.matrix()
    assert abs(matrix - matrix.T).max() == 0 and abs(matrix.sum(axis=1)).max() < 1e-12
    # 12 vertical links, 11 + 11 diagonal ones (none through the tip), 2 folded at the left edge; both directions
    assert len(cuts.rows) == 2 * (12 + 11 + 11 + 1)
    assert not SlitCuts.for_scene({**SCENE, "notches": []}, grid)


def test_no_flux_across_a_slit():
    """phi = 1 on one face and 0 on the other: along the slit (away from its tip) the cut
    Laplacian is zero, the uncut one is not; beyond the tip the jump still diffuses."""
    grid, cuts = _setup()
    ny, nx = grid.shape
    phi = np.zeros(grid.shape)
    phi[ny // 2:] = 1.0
    zero = np.zeros(grid.shape)
    reaction = GC / LC
    cut = PixelEquation(GC, LC, grid.h_px, "replicate", cuts).residual_on(phi, zero, (slice(0, ny), slice(0, nx)), normalised=False)
    uncut = PixelEquation(GC, LC, grid.h_px, "replicate").residual_on(phi, zero, (slice(0, ny), slice(0, nx)), normalised=False)
    along = (slice(ny // 2 - 1, ny // 2 + 1), slice(0, 10))
    np.testing.assert_allclose(cut[along], reaction * phi[along], rtol=0, atol=1e-9 * reaction)
    assert np.abs(uncut[along] - reaction * phi[along]).min() > 0.1 * GC * LC / grid.h_px**2
    beyond = (slice(ny // 2 - 1, ny // 2 + 1), slice(14, nx))
    np.testing.assert_allclose(cut[beyond], uncut[beyond])


@pytest.mark.parametrize("padding", ["replicate", "zeros"])
def test_exact_solver_with_cuts_is_the_direct_solution(padding):
    grid, cuts = _setup(padding=padding)
    history = _history(grid)
    phi = solve_pixel_equation(history, GC, LC, grid.h_px, padding, rtol=1e-12, cuts=cuts)
    diffusion = GC * LC / grid.h_px**2
    system = scipy.sparse.diags(GC / LC + 2 * history.ravel()) - diffusion * (laplacian_matrix(*grid.shape, padding) - cuts.matrix())
    direct = scipy.sparse.linalg.spsolve(system.tocsc(), 2 * history.ravel()).reshape(grid.shape)
    np.testing.assert_allclose(phi, direct, atol=1e-9)
    assert np.abs(normalised_residual(phi, history, GC, LC, grid.h_px, padding, cuts)).max() < 1e-8
    # the cut operator is still an M-matrix with row sums >= Gc/lc + 2H (the certificate's premise)
    off = system - scipy.sparse.diags(system.diagonal())
    assert off.max() <= 0 and (np.asarray(system.sum(axis=1)).ravel() >= GC / LC + 2 * history.ravel() - 1e-6).all()


def test_certificate_holds_on_a_cut_grid():
    """max |r| (normalised, cut residual) bounds max |phi - exact| for any perturbation."""
    grid, cuts = _setup()
    history = _history(grid, seed=1)
    exact = solve_pixel_equation(history, GC, LC, grid.h_px, "replicate", rtol=1e-13, cuts=cuts)
    assert_certificate_bounds_the_error(exact, history, GC, LC, grid.h_px, cuts)


@pytest.mark.parametrize("compiled", [True, False])
def test_correction_reaches_the_cut_solution(compiled, monkeypatch):
    """The verified step's box solve (compiled multigrid-CG, and its numpy fallback) on a box
    that the slit crosses converges to the cut equation's solution, certified."""
    import ifenn.pixel_equation.numpy_backend as numpy_backend

    if not compiled:
        monkeypatch.setattr(numpy_backend, "compiled_kernel", lambda: None)
    elif numpy_backend.compiled_kernel() is None:
        pytest.skip("no C++ compiler: the compiled kernel is not built here")
    grid, cuts = _setup()
    history = _history(grid, seed=3)
    exact = solve_pixel_equation(history, GC, LC, grid.h_px, "replicate", rtol=1e-13, cuts=cuts)
    equation = PixelEquation(GC, LC, grid.h_px, "replicate", cuts)
    for box in ((slice(10, 30), slice(0, 24)), (slice(0, 40), slice(0, 40))):
        phi = exact.copy()
        phi[box] = 2 * history[box] / (GC / LC + 2 * history[box])  # the local solution: far off near the tip
        worst, iterations = equation.solve_box(phi, history, box, target=1e-6)
        assert worst <= 1e-6 and iterations > 0
        assert np.abs(equation.residual_on(phi, history, box)).max() <= 1.01e-6
        assert np.abs(phi - exact).max() <= 2e-6


def test_multigrid_levels_keep_the_cut():
    """The V-cycle's coarse levels redraw the slit at their own spacing (a cut stays a cut on each
    level whose cells the slit's line runs between): a cold whole-image solve under shear at
    lc/h_px = 9 (300 x 300 pixels) takes 6 iterations against 4 without a slit (9 when only the
    finest level was cut). The coarse links are those of the slit at the coarser spacing, symmetric."""
    import ifenn.pixel_equation.numpy_backend as numpy_backend

    if numpy_backend.compiled_kernel() is None:
        pytest.skip("no C++ compiler: the compiled kernel is not built here")
    scene = {**SCENE, "elements": [150, 150]}
    grid, cuts = _setup(scene)
    history = _history(grid)
    counts = {}
    for name, c in (("plain", None), ("slit", cuts)):
        equation = PixelEquation(GC, 0.03, grid.h_px, "replicate", c)
        phi = 2 * history / (GC / 0.03 + 2 * history)
        worst, counts[name] = equation.solve_box(phi, history, (slice(0, 300), slice(0, 300)), 5e-4)
        assert worst <= 5e-4
    assert counts["slit"] <= counts["plain"] + 3
    rows, cols, weights = cuts.coarse_links((slice(0, 300), slice(0, 300)), 1, (150, 150))
    assert rows.size and set(zip(rows.tolist(), cols.tolist(), strict=True)) == set(zip(cols.tolist(), rows.tolist(), strict=True))
    assert ((rows // 150 == 74) | (rows // 150 == 75)).all()   # the rows next to y = 0 only
    # at level 2 (cells of 4 pixels) the slit's line (pixel row 150) runs through cells: nothing to cut
    assert cuts.coarse_links((slice(0, 300), slice(0, 300)), 2, (75, 75))[0].size == 0


def test_mode_one_phi_nearly_unchanged_shear_phi_changed():
    """Under mode I (history mirror-symmetric about the slit) nothing flows across it: the cut
    and uncut solutions agree within 2 % of the peak; under shear the uncut one is too weak at
    the tip (damage leaks to the other face)."""
    grid, cuts = _setup()
    for shear, close in ((False, True), (True, False)):
        history = _history(grid, shear=shear)
        cut = solve_pixel_equation(history, GC, LC, grid.h_px, "replicate", cuts=cuts)
        uncut = solve_pixel_equation(history, GC, LC, grid.h_px, "replicate")
        change = np.abs(cut - uncut).max() / cut.max()
        assert (change < 0.02) if close else (change > 0.05 and uncut.max() < cut.max()), (shear, change)


def test_shear_loaded_slit_pixel_solution_tracks_fem(quick_config, quick_spec, tmp_path):
    """FEM's own history maps on the shear-loaded single-edge-notched square (quick scene
    snt-shear): the pixel solution with the slit cut reaches FEM's max phi within 7 % at three
    increments before the peak (it resolves the field at h/2, FEM at h: a few % above); without
    the cut it is farther off and too low (damage leaks to the other face: 9 % low here, 18 %
    at the paper's scale)."""
    from ifenn import run_files
    from ifenn.fem.mesh import build_mesh, write_mesh
    from ifenn.fem.solver import run_fem

    scene = quick_config["scenes"]["snt-shear"]
    spec = quick_spec("snt1-II", scene=scene, scene_name="snt-shear", load=[1e-3 * k for k in range(1, 13)], save_fields=[6, 9, 12],
                      save_every=0, checkpoint_every=100)
    write_mesh(build_mesh(scene), tmp_path / "mesh.xdmf")
    run_fem(spec, tmp_path / "mesh.xdmf", tmp_path / "fem", progress=False)
    grid = PixelGrid.for_scene(scene)
    cuts = SlitCuts.for_scene(scene, grid, "replicate")
    Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
    states = run_files.read_states(tmp_path / "fem" / "fields.h5", [6, 9, 12], keys=run_files.MAP_KEYS)
    for state in states:
        fem = state["phase_field_gp"].max()
        cut = solve_pixel_equation(state["history"], Gc, lc, grid.h_px, "replicate", cuts=cuts).max()
        uncut = solve_pixel_equation(state["history"], Gc, lc, grid.h_px, "replicate").max()
        assert 0.1 < fem < 0.6 and abs(cut / fem - 1) <= 0.07, (state["increment"], fem, cut)
        assert uncut < fem and abs(uncut / fem - 1) > abs(cut / fem - 1) + 0.02, (state["increment"], fem, cut, uncut)


def test_training_residual_knows_the_slits():
    """The torch residual (the training loss) with the cuts equals the verified step's residual,
    and the exact cut solution makes it vanish."""
    import torch

    from ifenn.pixel_equation.torch_backend import residual

    grid, cuts = _setup()
    history = _history(grid, seed=4)
    phi = solve_pixel_equation(history, GC, LC, grid.h_px, "replicate", rtol=1e-13, cuts=cuts)
    as_tensor = (lambda a: torch.as_tensor(a, dtype=torch.float64)[None, None])  # noqa: E731
    trial = phi + 0.01 * np.random.default_rng(5).standard_normal(grid.shape)
    torch_r = residual(as_tensor(trial), as_tensor(history), GC, LC, grid.h_px, "replicate", cuts)[0, 0].numpy()
    numpy_r = normalised_residual(trial, history, GC, LC, grid.h_px, "replicate", cuts) * (GC / LC + 2 * history)
    # R of the torch form is (Gc/lc + 2H) phi - ... - 2H: the same as the verified step's
    np.testing.assert_allclose(torch_r, numpy_r, rtol=1e-9, atol=1e-9 * np.abs(numpy_r).max())
    exact_r = residual(as_tensor(phi), as_tensor(history), GC, LC, grid.h_px, "replicate", cuts)
    assert float(exact_r.abs().max()) < 1e-8 * float(2 * history.max())
    with pytest.raises(ValueError, match="slit cuts of a"):
        residual(as_tensor(phi[:-2]), as_tensor(history[:-2]), GC, LC, grid.h_px, "replicate", cuts)


def test_training_loss_on_crops_knows_the_slits():
    """The training loss on crops (each with its own share of the slit's cuts) adds up to the
    full image's loss with the cuts, as the uncut one does without; and training with the cuts
    is deterministic for a seed."""
    import torch

    from ifenn.network.picnn import PICNN
    from ifenn.network.training import make_tiles, train_picnn
    from ifenn.pixel_equation.torch_backend import physics_loss

    grid, cuts = _setup()
    torch.manual_seed(4)
    model = PICNN(padding="replicate").double()
    capped = np.minimum(_history(grid), model.history_cap)[None]
    tiles, _ = make_tiles(capped, tile_size=20, context=9, process_zone_history=GC / LC, process_zone_margin_px=4)
    crop = tuple(tiles.history.shape[-2:])
    stacked = SlitCuts.stacked([cuts.crop((slice(cy, cy + crop[0]), slice(cx, cx + crop[1]))) for _, cy, cx in tiles.origins])
    image = torch.as_tensor(capped[0])[None, None]
    full = physics_loss(model.phase_field(image), image, GC, LC, grid.h_px, "replicate", cuts=cuts)
    tiled = physics_loss(model.phase_field(tiles.history), tiles.history, GC, LC, grid.h_px, "replicate", tiles.weight, stacked)
    torch.testing.assert_close(tiled, full, rtol=1e-10, atol=0.0)
    from ifenn.pixel_equation.torch_backend import residual

    with torch.no_grad():  # the cuts change the residual on the slit's two rows of pixels only
        phi = model.phase_field(image)
        change = (residual(phi, image, GC, LC, grid.h_px, "replicate", cuts) - residual(phi, image, GC, LC, grid.h_px, "replicate"))
    rows, cols = np.nonzero(change[0, 0].numpy())
    assert set(rows) == {19, 20} and cols.max() <= 12
    settings = {"epochs": 4, "full_image_epochs": 2, "lr": 1e-2, "channels": (1, 4, 4, 1), "tile_size": 20}
    runs = [train_picnn([capped[0]], grid.h_px, GC, LC, settings, seed=1, progress=False, cuts=cuts)[1].loss for _ in range(2)]
    np.testing.assert_array_equal(runs[0], runs[1])
