"""Pictures of a run for notebooks and reports: the particles coloured by a field (pyvista,
off-screen), a field along a segment against the exact solution (matplotlib) and an animation
of the stored frames (GIF, or MP4 with imageio-ffmpeg).

Every picture is a `Picture`: it shows itself inline in Jupyter and ``save(path)`` writes a PNG.
Nothing here opens a window; for an interactive view, ``plotter(result, off_screen=False).show()``.
On Linux without a display, VTK is pointed at its EGL (else OSMesa) render window, which renders
with Mesa on the CPU; ``python -m skdgmpm.pictures`` checks that it works (``.ci/run`` does).

    python -m skdgmpm.pictures [picture.png]
"""
import base64
import ctypes.util
import io
import os
import sys
from pathlib import Path

import numpy as np

from . import output, plots
from .errors import InputError


class Picture:
    """A rendered picture: ``array`` (height, width, 3) uint8 pixels, ``figure`` the matplotlib
    `Figure` of a line plot (None for a pyvista picture), ``savefig(path)`` / ``save(path)`` write
    it. Shown inline by Jupyter."""

    def __init__(self, array=None, figure=None):
        self._array, self.figure = array, figure

    @property
    def array(self):
        if self._array is None:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            canvas = FigureCanvasAgg(self.figure)
            canvas.draw()
            self._array = np.asarray(canvas.buffer_rgba())[..., :3].copy()
        return self._array

    def save(self, path):
        """Write a PNG; returns the path."""
        path = Path(path)
        path.write_bytes(self._repr_png_())
        return path

    def savefig(self, path, **options):
        """As matplotlib's ``Figure.savefig`` for a line plot (any format, ``dpi=``, ...); a
        rendered picture is written as a PNG. Returns the path."""
        if self.figure is None:
            return self.save(path)
        self.figure.savefig(path, **options)
        return Path(path)

    def _repr_png_(self):
        buffer = io.BytesIO()
        if self.figure is not None:
            self.figure.savefig(buffer, format="png", dpi=self.figure.dpi)
        else:
            from PIL import Image
            Image.fromarray(self.array).save(buffer, format="png")
        return buffer.getvalue()

    def __repr__(self):
        h, w = self.array.shape[:2]
        return f"<Picture {w}x{h}>"


class Animation:
    """An animation file written by `animate`; Jupyter shows it inline (GIF image, MP4 video)."""

    def __init__(self, path, n_frames):
        self.path, self.n_frames = Path(path), n_frames

    def __fspath__(self):
        return str(self.path)

    def _repr_html_(self):
        data = base64.b64encode(self.path.read_bytes()).decode()
        if self.path.suffix == ".mp4":
            return f'<video controls loop src="data:video/mp4;base64,{data}"></video>'
        return f'<img src="data:image/gif;base64,{data}"/>'

    def __repr__(self):
        return f"<Animation {self.path} ({self.n_frames} frames)>"


def frame(result, time=None):
    """The stored state nearest ``time`` (s); None: the final state.

    ``run(frames=N)`` stores N + 1 states, evenly spaced in time, the initial one included.
    """
    if time is None:
        return result.state
    times = np.array([f.t for f in result.frames])
    if not 0.0 <= time <= times[-1] * (1 + 1e-9):
        raise InputError(f"time = {time!r}: the stored frames span [0, {times[-1]:.6g}] s")
    return result.frames[int(np.argmin(np.abs(times - time)))]


def field_values(result, state, field):
    """Particle values of ``field``: any name of `output.particle_fields`, ``speed`` (|v|) or
    ``material`` (the index of each particle's material)."""
    fields = output.particle_fields(result.stepper, state)
    d = result.scene.dim
    fields["speed"] = np.linalg.norm([fields[f"v{i + 1}"] for i in range(d)], axis=0)
    fields["material"] = result.disc.particles.material.astype(float)
    if field not in fields:
        raise InputError(f"field = {field!r} is not a particle field (known: {', '.join(fields)})")
    return fields[field]


# fields that are non-negative by definition (the equivalent plastic strain, the speed): shown
# from 0 on a sequential colour map, where a diverging one centred on 0 would waste half its colours
SEQUENTIAL = ("eqp", "speed")
# fields whose values are labels, not amounts: one distinct colour each
CATEGORICAL = ("material",)
# a field whose values of one sign reach at most this fraction of the other sign's extreme is shown
# as one-signed (the partial impact's P11: compression, with overshoots of 3 % into tension)
ONE_SIGNED = 0.1


def colour_range(values, field=None):
    """(lo, hi) over a list of arrays. From 0 for the non-negative fields of `SEQUENTIAL`; for a
    field of both signs, symmetric about 0 (zero is then the white middle of the diverging map),
    unless it is almost one-signed (the minority sign reaches at most `ONE_SIGNED` of the
    majority's extreme): then the values' own range, on a sequential map (`default_cmap`), so
    that the main wave takes the whole colour scale. `CATEGORICAL` fields: one bin per value."""
    lo, hi = min(float(v.min()) for v in values), max(float(v.max()) for v in values)
    if field in CATEGORICAL:
        return float(np.floor(lo)) - 0.5, float(np.ceil(hi)) + 0.5
    if field in SEQUENTIAL:
        lo = 0.0
    elif lo < 0.0 < hi and min(-lo, hi) > ONE_SIGNED * max(-lo, hi):
        lo, hi = -max(-lo, hi), max(-lo, hi)
    if lo == hi:
        lo, hi = lo - max(abs(lo), 1.0) * 1e-3, hi + max(abs(hi), 1.0) * 1e-3
    return lo, hi


def default_cmap(field, clim=None):
    """The colour map of ``field`` over the range ``clim`` (`colour_range`): categorical (tab10)
    for `CATEGORICAL` fields; viridis for `SEQUENTIAL` ones; diverging (coolwarm: negative blue,
    0 white, positive red) for a range symmetric about 0; otherwise sequential in the same colours,
    white at 0 and darkest at the largest magnitude: Blues for mostly negative values, Reds for
    mostly positive ones."""
    if field in CATEGORICAL:
        return "tab10"
    if field in SEQUENTIAL:
        return "viridis"
    if clim is None:
        return "coolwarm"
    lo, hi = clim
    if lo < 0.0 < hi and np.isclose(-lo, hi, rtol=1e-9):
        return "coolwarm"
    return "Blues_r" if -lo > hi else "Reds"


def _pad3(a):
    return np.column_stack([a, np.zeros((len(a), 3 - a.shape[1]))])


def use_offscreen_window():
    """On Linux without a display, make VTK open an EGL (else OSMesa) render window, which needs
    no X server. Leaves an explicit ``VTK_DEFAULT_OPENGL_WINDOW`` alone."""
    if (not sys.platform.startswith("linux") or os.environ.get("DISPLAY")
            or os.environ.get("WAYLAND_DISPLAY") or "VTK_DEFAULT_OPENGL_WINDOW" in os.environ):
        return
    for library, window in (("EGL", "vtkEGLRenderWindow"), ("OSMesa", "vtkOSMesaRenderWindow")):
        if ctypes.util.find_library(library):
            os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = window
            return


def offscreen_pyvista():
    """The pyvista module, with VTK set to render without a display where there is none."""
    try:
        import pyvista
    except ImportError:
        raise ImportError("pictures of particles need pyvista: pip install 'skdgmpm[viz]'") from None
    use_offscreen_window()
    return pyvista


def grid_mesh(result, z=0.0):
    """The background grid (reference configuration) as a pyvista mesh."""
    pv = offscreen_pyvista()
    m = result.disc.grid.mesh
    kind = pv.CellType.LINE if m.dim() == 1 else pv.CellType.QUAD
    cells = np.column_stack([np.full(m.nelements, m.t.shape[0]), m.t.T]).ravel()
    points = _pad3(m.p.T)
    points[:, 2] = z
    return pv.UnstructuredGrid(cells, np.full(m.nelements, kind, dtype=np.uint8), points)


def _positions(result, state, magnify):
    X = result.X
    return _pad3(X + magnify * (state.x - X))


def plotter(result, field="P11", time=None, grid=True, off_screen=True, window_size=(900, 450),
            clim=None, cmap=None, point_size=None, magnify=1.0, title=None):
    """A pyvista Plotter showing the particles at ``time`` in the current configuration,
    coloured by ``field``, over the background grid (``grid=False`` hides it).

    ``magnify`` scales the displacement x - X (small-strain scenes show nothing at 1);
    ``point_size`` is in pixels (default: about one particle spacing); ``clim`` = (lo, hi)
    (default: the values' range, symmetric about 0 if they take both signs; from 0 for eqp and
    speed; the values' own range when they are almost all of one sign); ``cmap`` (default:
    `default_cmap`: diverging for a symmetric range, sequential for one-signed fields, categorical
    for material). ``off_screen=False``
    gives a plotter whose ``show()`` opens a window (needs a display).
    """
    return _plotter(result, field, time, grid, off_screen, window_size, clim, cmap, point_size,
                    magnify, title)[0]


def _plotter(result, field, time, grid, off_screen, window_size, clim=None, cmap=None,
             point_size=None, magnify=1.0, title=None, bounds=None):
    pv = offscreen_pyvista()
    state = frame(result, time)
    cloud = pv.PolyData(_positions(result, state, magnify))
    cloud[field] = field_values(result, state, field)
    categorical = {}
    if field in CATEGORICAL:                      # one colour and one named entry per material
        laws = [f"{getattr(m, 'law_name', type(m).__name__)}, E = {m.E:.3g} Pa"
                for m in result.stepper.materials.materials]
        clim = (-0.5, len(laws) - 0.5)
        if cmap is None:
            from matplotlib import colormaps
            from matplotlib.colors import ListedColormap
            cmap = ListedColormap(colormaps["tab10"].colors[: len(laws)])
        categorical = {"n_colors": len(laws), "annotations": {float(k): f"{k}: {law}" for k, law in enumerate(laws)}}
    clim = colour_range([cloud[field]], field) if clim is None else clim
    cmap = default_cmap(field, clim) if cmap is None else cmap
    pl = pv.Plotter(off_screen=off_screen, window_size=list(window_size))
    pl.set_background("white")
    size = float(np.ptp(result.X, axis=0).max())
    if grid:
        pl.add_mesh(grid_mesh(result, z=-1e-3 * size), style="wireframe", color="#bbbbbb", line_width=1)
    # the bar's title is written to its left (as a VTK title it shares the band above the bar with
    # the tick labels and overlapped them); ticks: the two ends and the middle
    bar = {"title": "", "color": "black", "fmt": "%.3g", "vertical": False,
           "n_labels": 0 if categorical else 3, "label_font_size": 12,
           "position_x": 0.3, "position_y": 0.03, "width": 0.55, "height": 0.1}
    if categorical:                               # the names go below the bar: lift it
        bar.update(position_y=0.09, height=0.06)
    points = pl.add_points(cloud, scalars=field, cmap=cmap, clim=clim, render_points_as_spheres=True,
                           point_size=point_size or 5, scalar_bar_args=bar, **categorical)
    pl.add_text(plots.field_label(field), position=(int(0.03 * window_size[0]), int(0.045 * window_size[1])),
                font_size=8, color="black", name="bar_title")
    pl.add_text(title or _title(result, state), font_size=10, color="black", name="title")
    pl.view_xy()
    pl.enable_parallel_projection()
    pl.reset_camera(bounds=bounds)
    _frame_camera(pl.camera, bounds if bounds is not None else pl.bounds, window_size)
    if point_size is None:
        spacing = np.median(result.disc.particles.volume) ** (1.0 / result.scene.dim)
        pixels = spacing * window_size[1] / (2 * pl.camera.parallel_scale)
        points.prop.point_size = float(np.clip(0.9 * pixels, 6, 30))
    return pl, cloud


def _frame_camera(camera, bounds, window_size):
    """Fit ``bounds`` between 20 % (colour bar below) and 92 % (title above) of the height."""
    lo, hi = np.reshape(bounds, (3, 2)).T
    width, height = (hi - lo)[:2]
    scale = 0.5 * max(height / 0.72, 1.04 * width * window_size[1] / window_size[0])
    centre = 0.5 * (lo + hi)
    centre[1] -= 0.12 * scale                     # body centre at 56 % of the height
    distance = np.linalg.norm(np.subtract(camera.position, camera.focal_point))
    camera.focal_point = tuple(centre)
    camera.position = tuple(centre + [0.0, 0.0, distance])
    camera.parallel_scale = scale


def _title(result, state):
    return f"{result.scene.get('title', result.scene.name)}: {result.summary()['method']}, t = {state.t:.4g} s"


def particles(result, field="P11", time=None, grid=True, path=None, **options):
    """Picture of the particles coloured by ``field`` at ``time`` (see `plotter` for options);
    also written to ``path`` (PNG) if given."""
    pl = plotter(result, field, time, grid, off_screen=True, **options)
    try:
        picture = Picture(pl.screenshot(return_img=True))
    finally:
        pl.close()
    if path is not None:
        picture.save(path)
    return picture


def line(result, field="P11", time=None, start=None, end=None, path=None, ax=None, label=None, exact=True):
    """``field`` along the segment [start, end] (reference coordinates; default the bar in 1D,
    the bottom line of particles in 2D) at ``time``, against the exact solution when there is one
    (``exact=False`` leaves it out; ``label`` names the particle values in the legend).

    Draws into ``ax`` and returns it if given (several runs on one axes); otherwise returns a
    `Picture` (``.figure``), written to ``path`` if given.
    """
    state = frame(result, time)
    if ax is not None:
        return plots.line(result, field, state, start, end, ax=ax, label=label, exact=exact)
    from matplotlib.figure import Figure        # no pyplot: the user's backend is left alone
    fig = Figure(figsize=(6.4, 3.6), dpi=100, layout="tight")
    plots.line(result, field, state, start, end, ax=fig.add_subplot(), label=label, exact=exact)
    picture = Picture(figure=fig)
    if path is not None:
        picture.save(path)
    return picture


def animate(result, path, field="P11", grid=True, fps=5, clim=None, window_size=(640, 320), **options):
    """Write the stored frames of ``result`` as an animation: ``.gif`` (Pillow) or ``.mp4``
    (imageio with imageio-ffmpeg). The colour range is that of all frames unless ``clim``."""
    path = Path(path)
    if path.suffix not in (".gif", ".mp4"):
        raise InputError(f"animation {path}: expected a .gif or .mp4 file name")
    if clim is None:
        clim = colour_range([field_values(result, f, field) for f in result.frames], field)
    magnify = options.get("magnify", 1.0)
    every = np.vstack([_positions(result, f, magnify) for f in result.frames])
    if grid:
        every = np.vstack([every, _pad3(result.disc.grid.mesh.p.T)])
    bounds = np.column_stack([every.min(axis=0), every.max(axis=0)]).ravel()
    pl, cloud = _plotter(result, field, 0.0, grid, True, window_size, clim=clim, bounds=bounds, **options)
    images = []
    try:
        for state in result.frames:
            cloud.points = _positions(result, state, magnify)
            cloud[field] = field_values(result, state, field)
            pl.add_text(_title(result, state), font_size=10, color="black", name="title")
            images.append(pl.screenshot(return_img=True))
    finally:
        pl.close()
    if path.suffix == ".gif":
        from PIL import Image
        frames = [Image.fromarray(a) for a in images]
        frames[0].save(path, save_all=True, append_images=frames[1:], duration=int(1000 / fps), loop=0)
    else:
        try:
            import imageio.v2 as imageio
        except ImportError:
            raise InputError(f"animation {path}: MP4 needs imageio and imageio-ffmpeg "
                             f"(pip install imageio imageio-ffmpeg), or write a .gif") from None
        with imageio.get_writer(path, fps=fps, macro_block_size=8) as writer:
            for a in images:
                writer.append_data(a)
    return Animation(path, len(images))


def check_rendering(path=None):
    """Render a small coloured point cloud off-screen and check the pixels vary; returns the
    `Picture` and the name of VTK's render window. Raises RuntimeError if the image is blank."""
    pv = offscreen_pyvista()
    pl = pv.Plotter(off_screen=True, window_size=[240, 160])
    pl.set_background("white")
    xy = np.random.default_rng(0).random((200, 2))
    pl.add_points(_pad3(xy), scalars=xy[:, 0], render_points_as_spheres=True, point_size=8)
    pl.view_xy()
    try:
        picture, window = Picture(pl.screenshot(return_img=True)), pl.ren_win.GetClassName()
    finally:
        pl.close()
    if picture.array.std() == 0:
        raise RuntimeError(f"off-screen rendering with {window} gave a blank image")
    if path is not None:
        picture.save(path)
    return picture, window


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    try:
        picture, window = check_rendering(argv[0] if argv else None)
    except Exception as exc:            # report any failure of the graphics stack in one line
        print(f"off-screen rendering fails: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    print(f"off-screen rendering works: {window}, {picture!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
