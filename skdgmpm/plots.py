"""Plots a person would rather look at than read (matplotlib, headless-safe)."""
import numpy as np

from .errors import InputError

#: units of the particle fields, by the name without its indices
UNITS = {"P": "Pa", "sigma": "Pa", "v": "m/s", "x": "m", "speed": "m/s"}


def field_label(field):
    """``P11 (Pa)``, ``v1 (m/s)``, ``F11``: the field name with its unit, if it has one."""
    unit = UNITS.get(field.rstrip("0123456789"))
    return f"{field} ({unit})" if unit else field


def _figure():
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    return plt


def energy(result, path=None, ax=None):
    """Kinetic, stored, dissipated (plastic work, where a law has it) and total energy, boundary
    work and the balance against time."""
    plt = _figure()
    fig = None
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 3.5))
    h = result.history
    for key in ("kinetic", "stored", "dissipated", "total", "external_work", "balance"):
        if key == "dissipated" and not np.any(h[key]):
            continue
        ax.plot(h["t"], h[key], label=key.replace("_", " "))
    ax.set_xlabel("t (s)")
    ax.set_ylabel("energy (J)")
    ax.legend(fontsize=8)
    ax.set_title(f"{result.scene.name}: energy")
    if fig is not None and path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return ax


def probes(result, path=None):
    """The probes' time histories: one panel per field, a curve per point (`skdgmpm.probes`)."""
    plt = _figure()
    pr = result.probes
    fig, axes = plt.subplots(len(pr.fields), 1, figsize=(6, 1.2 + 2.1 * len(pr.fields)), sharex=True, squeeze=False)
    for ax, f in zip(axes[:, 0], pr.fields):
        for name, X in zip(pr.names, pr.X):
            ax.plot(pr.t, pr[name, f], label=f"{name} (X = {', '.join(f'{c:.4g}' for c in X)} m)")
        ax.set_ylabel(field_label(f))
    axes[0, 0].legend(fontsize=8)
    axes[0, 0].set_title(f"{result.scene.name}: probes")
    axes[-1, 0].set_xlabel("t (s)")
    if path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig


def line_particles(result, axis=0):
    """Particles on the line of smallest transverse coordinate (the bottom line in 2D), sorted."""
    X = result.X
    if X.shape[1] == 1:
        return np.argsort(X[:, 0])
    other = X[:, 1 - axis]
    sel = np.flatnonzero(np.isclose(other, other.min()))
    return sel[np.argsort(X[sel, axis])]


def segment_particles(result, start, end, tol=None):
    """Particles whose reference position lies within ``tol`` of the segment [start, end], sorted
    along it, and their distance from ``start``. ``tol`` defaults to half a particle spacing."""
    X = result.X
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    length = np.linalg.norm(b - a)
    if a.shape != (X.shape[1],) or b.shape != a.shape or not length > 0:
        raise InputError(f"segment {start!r} -> {end!r}: expected two distinct points of dimension {X.shape[1]}")
    if tol is None:
        tol = 0.5 * np.median(result.disc.particles.volume) ** (1.0 / X.shape[1])
    s = (X - a) @ (b - a) / length
    off = np.linalg.norm(X - a - np.outer(s / length, b - a), axis=1)
    sel = np.flatnonzero((off <= tol) & (s >= -tol) & (s <= length + tol))
    order = np.argsort(s[sel])
    return sel[order], s[sel][order]


def bottom_segment(result):
    """The bar (1D), or in 2D the horizontal line through the particle of smallest X2 across the
    body's X1 range, as (start, end): the bottom row of a structured grid; on an unstructured mesh
    (one particle lowest) the particles within half a spacing of that line (`segment_particles`)."""
    if result.X.shape[1] == 1:
        idx = line_particles(result)
        return result.X[idx[0]], result.X[idx[-1]]
    X = result.X
    y0 = X[:, 1].min()
    return np.array([X[:, 0].min(), y0]), np.array([X[:, 0].max(), y0])


def line(result, field="P11", state=None, start=None, end=None, ax=None, label=None, exact=True):
    """``field`` along the segment [start, end] (default: the bottom line) at the particles,
    against the exact solution on the segment when the scene has one (and ``exact``). Draws into
    ``ax``; ``label`` names the particle values in the legend (default: method and time)."""
    state = state or result.state
    if start is None and end is None:
        start, end = bottom_segment(result)
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    idx, s = segment_particles(result, a, b)
    along = [k for k in range(len(a)) if b[k] > a[k] and np.allclose(np.delete(b - a, k), 0.0)]
    k = along[0] if along else None             # the segment runs along axis k: plot against X_k
    abscissa = (lambda dist: a[k] + dist) if along else (lambda dist: dist)
    values = result.fields(state)[field][idx]
    ax.plot(abscissa(s), values, "o", ms=3, label=label or f"{result.summary()['method']} (t = {state.t:.3g} s)")
    known = result.exact.fields(a[None, :], state.t) if exact and result.exact is not None else {}
    if field in known:
        dist = np.linspace(0.0, np.linalg.norm(b - a), 2000)
        points = a + np.outer(dist / dist[-1], b - a)
        ax.plot(abscissa(dist), result.exact.fields(points, state.t)[field], "k-", lw=1, label="exact")
    ax.set_xlabel(f"X{k + 1} (m)" if along else f"distance from ({', '.join(f'{x:.4g}' for x in a)}) (m)")
    ax.set_ylabel(field_label(field))
    ax.legend(fontsize=8)
    ax.set_title(result.scene.get("title", result.scene.name))
    return ax


def profile(result, path=None, field="P11", state=None, ax=None):
    """A field along the bottom line (2D) or the bar (1D), with the exact solution if any."""
    fig = None
    if ax is None:                    # only then touch pyplot: a given axes keeps the user's backend
        plt = _figure()
        fig, ax = plt.subplots(figsize=(6, 3.5))
    line(result, field, state, ax=ax)
    if fig is not None and path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return ax


def field_map(result, field, path=None, state=None, ax=None, cmap="viridis"):
    """A 2D map of ``field`` at the points' current positions (a sequential colour map: eqp and
    other fields that only grow from zero)."""
    state = state or result.state
    fig = None
    if ax is None:
        plt = _figure()
        fig, ax = plt.subplots(figsize=(6, 4))
    values = result.fields(state)[field]
    size = 4e4 / max(len(values), 1)
    sc = ax.scatter(state.x[:, 0], state.x[:, 1], c=values, s=min(max(size, 1.0), 30.0), cmap=cmap,
                    vmin=0.0 if values.min() >= 0 else None, marker="s", linewidths=0)
    ax.set_aspect("equal")
    ax.set_xlabel("x1 (m)")
    ax.set_ylabel("x2 (m)")
    ax.set_title(f"{result.scene.name}: {field} at t = {state.t:.3g} s")
    if fig is not None:
        fig.colorbar(sc, ax=ax, label=field_label(field), shrink=0.8)
        if path is not None:
            fig.tight_layout()
            fig.savefig(path, dpi=110)
            plt.close(fig)
    return ax
