"""Pictures of a run: off-screen particle pictures (pyvista), line plots against the exact
solution (matplotlib), animations, and the one-line repr of a result."""
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from skdgmpm import pictures
from skdgmpm.errors import InputError
from skdgmpm.run import run


@pytest.fixture(scope="module")
def rendering():
    """Off-screen rendering works here (checked in a child process: a graphics stack that cannot
    open a window may abort the process). `.ci/run` installs what it needs; where it cannot,
    the picture tests are skipped with the reason."""
    pytest.importorskip("pyvista")
    probe = subprocess.run([sys.executable, "-m", "skdgmpm.pictures"], capture_output=True, text=True,
                           timeout=120)
    if probe.returncode != 0:
        pytest.skip(f"no off-screen rendering on this machine: {probe.stderr.strip()[-300:]}")


@pytest.fixture(scope="module")
def wave():
    """2D scene with an exact solution, 6 stored frames."""
    return run("standing_wave_2d", ["grid.cells=[8, 8]"], progress=False, frames=5)


@pytest.fixture(scope="module")
def bar():
    return run("bar_elastic_1d", ["grid.cells=60", "run.t_end=1e-3"], progress=False, frames=4)


def _pixels(path):
    image = np.asarray(Image.open(path).convert("RGB"), dtype=float)
    return image


def test_plot_writes_a_png_whose_pixels_vary(rendering, wave, tmp_path):
    picture = wave.plot(field="P11", time=5e-5, path=tmp_path / "p11.png", window_size=(400, 250))
    path = tmp_path / "p11.png"
    assert path.stat().st_size > 1000
    image = _pixels(path)
    assert image.shape == (250, 400, 3)
    assert image.std() > 10                                   # not a blank image
    colours = np.unique(image.reshape(-1, 3), axis=0)
    assert len(colours) > 50                                  # a colour map, not two flat colours
    saturated = np.ptp(image, axis=2) > 60                   # blue and red particles, not grey
    assert saturated.mean() > 0.05
    assert picture.array.shape == image.shape
    assert picture._repr_png_().startswith(b"\x89PNG")     # what Jupyter shows inline


def test_grid_is_optional_and_drawn_when_asked(rendering, wave):
    with_grid = wave.plot("v1", grid=True, window_size=(300, 200)).array.astype(float)
    without = wave.plot("v1", grid=False, window_size=(300, 200)).array.astype(float)
    assert np.abs(with_grid - without).max() > 50


def test_time_picks_the_nearest_stored_frame(wave):
    times = [f.t for f in wave.frames]
    assert len(times) == 6
    assert pictures.frame(wave, times[2] + 1e-9) is wave.frames[2]
    assert pictures.frame(wave) is wave.state
    with pytest.raises(InputError, match="stored frames span"):
        pictures.frame(wave, 1.0)
    with pytest.raises(InputError, match="known: .*P11"):
        pictures.field_values(wave, wave.state, "P33")


@pytest.mark.parametrize("case", ["bar", "wave"])
def test_line_plot_against_the_exact_solution(case, request, tmp_path):
    result = request.getfixturevalue(case)
    frame = result.frames[3]
    fig = Figure()
    ax = result.plot_line("P11", time=frame.t, ax=fig.add_subplot())
    markers, exact = ax.lines
    assert exact.get_label() == "exact" and f"t = {frame.t:.3g}" in markers.get_label()
    X = result.X
    bottom = np.isclose(X[:, -1], X[:, -1].min()) if result.scene.dim == 2 else np.ones(len(X), bool)
    assert len(markers.get_xdata()) == bottom.sum()
    order = np.argsort(X[bottom, 0])
    np.testing.assert_allclose(markers.get_ydata(), result.fields(frame)["P11"][bottom][order])
    points = np.column_stack([exact.get_xdata(), np.full_like(exact.get_xdata(), X[:, -1].min())])
    np.testing.assert_allclose(exact.get_ydata(), result.exact.fields(points[:, : result.scene.dim], frame.t)["P11"])
    # the numbers are close to the exact ones: the plot compares like with like
    interp = np.interp(markers.get_xdata(), exact.get_xdata(), exact.get_ydata())
    assert np.abs(interp - markers.get_ydata()).mean() < 0.3 * np.abs(exact.get_ydata()).max()

    picture = result.plot_line("P11", path=tmp_path / "line.png")
    assert picture.figure is not None and _pixels(tmp_path / "line.png").std() > 10


def test_line_along_a_given_segment(wave):
    """Particles within half a spacing of the segment: one row on a row of particles, both rows
    when the segment runs half-way between them (8 cells x 2 particles per row)."""
    on_row = wave.plot_line("v1", start=[0.0, 0.53125], end=[1.0, 0.53125], ax=Figure().add_subplot())
    between = wave.plot_line("v1", start=[0.0, 0.5], end=[1.0, 0.5], ax=Figure().add_subplot())
    assert len(on_row.lines[0].get_xdata()) == 16 and len(between.lines[0].get_xdata()) == 32
    diagonal = wave.plot_line("v1", start=[0.0, 0.0], end=[1.0, 1.0], ax=Figure().add_subplot())
    assert diagonal.get_xlabel().startswith("distance from") and len(diagonal.lines) == 2
    with pytest.raises(InputError, match="segment"):
        wave.plot_line("v1", start=[0.0, 0.5], end=[0.0, 0.5])


def test_animation_has_one_frame_per_stored_state(rendering, wave, tmp_path):
    animation = wave.animate(tmp_path / "wave.gif", field="v1", window_size=(240, 160))
    image = Image.open(tmp_path / "wave.gif")
    assert image.n_frames == len(wave.frames) == animation.n_frames == 6
    image.seek(0)
    first = np.asarray(image.convert("RGB"), dtype=float)
    image.seek(3)
    later = np.asarray(image.convert("RGB"), dtype=float)
    assert first.std() > 10 and np.abs(first - later).max() > 50      # the particles change colour
    assert "data:image/gif;base64," in animation._repr_html_()
    with pytest.raises(InputError, match=r"\.gif or \.mp4"):
        wave.animate(tmp_path / "wave.avi")


def test_mp4_needs_imageio_ffmpeg_or_says_so(rendering, wave, tmp_path):
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        with pytest.raises(InputError, match="imageio-ffmpeg"):
            wave.animate(tmp_path / "wave.mp4", window_size=(240, 160))
    else:
        assert wave.animate(tmp_path / "wave.mp4", window_size=(240, 160)).path.stat().st_size > 0


def test_repr_is_one_line_with_scene_method_steps_time_and_errors(wave, bar):
    text = repr(wave)
    assert "\n" not in text and len(text) < 200
    assert text.startswith("<Result standing_wave_2d: dgmpm (euler, dcu), ok,")
    assert f"{wave.state.step} steps to t = {wave.state.t:.4g} s" in text
    assert f"P11 {wave.errors['P11']['L2_rel']:.2e}" in text and "v1" in text
    assert repr(bar).startswith("<Result bar_elastic_1d: dgmpm (euler), ok,")


def test_non_negative_fields_get_a_sequential_range_from_zero():
    """eqp (and speed) start at 0 on a sequential map; a field of both signs is symmetric about 0
    on the diverging map (0 white); a field (almost) all of one sign gets its own range on a
    sequential map in the sign's colour (issue 18: the partial impact's P11, compression with 3 %
    overshoots into tension, was pale on a symmetric range)."""
    from skdgmpm.pictures import colour_range, default_cmap
    eqp = np.array([0.0, 0.0, 0.02, 0.064])
    assert colour_range([eqp], "eqp") == (0.0, 0.064) and default_cmap("eqp") == "viridis"
    assert colour_range([eqp], "P11") == (0.0, 0.064) and default_cmap("P11", (0.0, 0.064)) == "Reds"
    assert colour_range([np.array([-2e9, 0.0])], "P11") == (-2e9, 0.0)
    assert default_cmap("P11", (-2e9, 0.0)) == "Blues_r"
    almost = [np.array([-5.18e8, -2e8, 0.0, 1.55e7])]                # 3 % into tension
    assert colour_range(almost, "P11") == (-5.18e8, 1.55e7) and default_cmap("P11", (-5.18e8, 1.55e7)) == "Blues_r"
    both = [np.array([-1e9, 0.0, 3e8])]                               # 30 %: both signs matter
    assert colour_range(both, "P11") == (-1e9, 1e9) and default_cmap("P11", (-1e9, 1e9)) == "coolwarm"
    assert colour_range([np.array([0.0, 1.0, 1.0])], "material") == (-0.5, 1.5)
    assert default_cmap("material") == "tab10"


def test_material_gets_one_flat_colour_per_material(rendering, tmp_path):
    """Two materials (regions by physical surface): the picture shows two hues, neither a shade of
    a diverging map's white middle; the legend names each law."""
    alu = 'material = {law = "linear_elastic", E = 7.0e10, nu = 0.33, rho = 2700.0}'
    r = run("partial_impact_2d", ['grid.mesh="plate_steel_alu_4x3.msh"', f'regions=[{{subdomain = "alu", {alu}}}]',
                                  "run.t_end=1e-5"], progress=False)
    pl = pictures.plotter(r, "material", window_size=(400, 250))
    try:
        mapper = pl.mapper
        assert mapper.lookup_table.n_values == 2 and tuple(mapper.scalar_range) == (-0.5, 1.5)
    finally:
        pl.close()
    image = _pixels(r.plot("material", grid=False, window_size=(400, 250), path=tmp_path / "m.png").save(tmp_path / "m.png"))
    hue = np.argmax(image, axis=2)[np.ptp(image, axis=2) > 80]      # saturated pixels: blue (2) and orange (0)
    assert (hue == 2).mean() > 0.2 and (hue == 0).mean() > 0.2


def test_line_picture_has_a_matplotlib_figure_and_savefig(bar, tmp_path):
    picture = bar.plot_line("P11")
    assert isinstance(picture.figure, Figure)
    assert picture.savefig(tmp_path / "line.pdf") == tmp_path / "line.pdf"
    assert (tmp_path / "line.pdf").read_bytes().startswith(b"%PDF")
    picture.savefig(tmp_path / "line.png", dpi=50)
    assert _pixels(tmp_path / "line.png").shape[1] == int(6.4 * 50)
