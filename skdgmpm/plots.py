"""Plots a person would rather look at than read (matplotlib, headless-safe)."""
import numpy as np


def _figure():
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    return plt


def energy(result, path=None, ax=None):
    """Kinetic, stored and total energy, boundary work and the balance against time."""
    plt = _figure()
    fig = None
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 3.5))
    h = result.history
    for key in ("kinetic", "stored", "total", "external_work", "balance"):
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


def line_particles(result, axis=0):
    """Particles on the line of smallest transverse coordinate (the bottom line in 2D), sorted."""
    X = result.X
    if X.shape[1] == 1:
        return np.argsort(X[:, 0])
    other = X[:, 1 - axis]
    sel = np.flatnonzero(np.isclose(other, other.min()))
    return sel[np.argsort(X[sel, axis])]


def profile(result, path=None, field="P11", state=None, ax=None):
    """A field along the bottom line (2D) or the bar (1D), with the exact solution if any."""
    plt = _figure()
    fig = None
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 3.5))
    state = state or result.state
    idx = line_particles(result)
    values = result.fields(state)[field][idx]
    X = result.X[idx, 0]
    ax.plot(X, values, "o", ms=3, label=f"{result.summary()['method']} (t = {state.t:.3g} s)")
    if result.exact is not None:
        fine = np.linspace(X.min(), X.max(), 2000)
        ax.plot(fine, result.exact.fields(fine[:, None], state.t)[field], "k-", lw=1, label="exact")
    ax.set_xlabel("X (m)")
    ax.set_ylabel(field)
    ax.legend(fontsize=8)
    ax.set_title(result.scene.get("title", result.scene.name))
    if fig is not None and path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return ax
