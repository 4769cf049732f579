"""Compiled face passes of first-order DGMPM: one loop over a face set per right-hand side.

For every face the pass gathers the side states through the trace operators (CSR rows, summed
in scipy's order), evaluates each side's tangent with the law's point function
(`skdgmpm.materials.points`), solves the linearised Riemann problem (`skdgmpm.equations`)
and, for CTU, splits each fluctuation on the characteristic basis of the two edges of
the cell it enters as soon as it is known, writing the two parts beside the face's flux; each
edge then gathers the parts it receives (`DGMPM.interface_flux`: a CSR row gather, signs as
weights), in face order. Every pass writes
its own rows only, so that it runs in chunks on several threads with the same bits
(`skdgmpm.parallel`). The corrections are proportional to Delta t (G = -dt / (2 h) B+ A dU): the
interior pass stores them per unit Delta t, so that a repeated attempt of the CFL guard reuses
the whole pass; the boundary pass (its stationary states depend on time) is redone, and
`euler_update` adds -int Phi (F* + dt G) to the residual as it advances the nodes.

Face-set arrays as in `skdgmpm.faces` ((nf, d) normals, (nf,) measures); a trace is the triple
(indptr, indices, data) of its CSR matrix; a CTU topology of one face side is
(h (nf,), normals (2, nf, 2), interior edge (2, nf), boundary edge (2, nf), sign (2, nf)) as built
by `DGMPM._setup_transverse` (empty arrays for DCU); the interior pass takes (h, normals (nf, 2, 2))
of each side, face-major so that a chunk of faces is a contiguous slice.
"""
from numba import njit

from skdgmpm.materials.points import tangent_call, tangent_point

from .equations import add_normal_flux, ctu_split, fluctuations, impedance, riemann, traction
from .faces import gather_row
from .kernel_cache import kernel_factory, scratch


# ---------------------------------------------------------------- point pieces (one face side)
@njit(cache=True, inline="always")
def _gather(trace, f, U, Q, rho, q, F, d):
    """`faces.gather_row` (Q into q, U's F part into the embedded F) and the row applied to rho
    (returned), summed in CSR order."""
    gather_row(trace, f, U, Q, q, F, d)
    indptr, indices, data = trace
    r = 0.0
    for k in range(indptr[f], indptr[f + 1]):
        r += data[k] * rho[indices[k]]
    return r


@njit(cache=True, inline="always")
def _integrate(trace, f, scale, value, w, R):
    """R[i] += w_i T[f, i] (scale value) over row f of a trace (value an array or a tuple), with
    the node weights w = (step, inv_M): w_i = step inv_M[i]."""
    indptr, indices, data = trace
    step, inv_M = w
    for k in range(indptr[f], indptr[f + 1]):
        n, t = indices[k], data[k]
        w_n = step * inv_M[n]
        for c in range(len(value)):
            R[n, c] += w_n * (t * (scale * value[c]))


@njit(cache=True, inline="always")
def _add_boundary_edges(edge_bnd, f, G_0, G_1, corr_bnd):
    """A boundary edge j of either of the two edges gets G_e - G_(1-e) into corr_bnd[j] (its ghost
    cell, a copy of the cell, sends back the opposite edge's part)."""
    j = edge_bnd[0, f]
    if j >= 0:
        for k in range(6):
            corr_bnd[j, k] += G_0[k] - G_1[k]
    j = edge_bnd[1, f]
    if j >= 0:
        for k in range(6):
            corr_bnd[j, k] += G_1[k] - G_0[k]


@njit(cache=True, inline="always")
def _split_into(w, C, rho, topo, f, G, k):
    """`equations.ctu_split` per unit Delta t (scale -1 / (2 h)) of a fluctuation entering one
    side of face f: its parts for the cell's two edges into G[f, k] and G[f, k + 1]."""
    h, normals = topo
    ok, G_0, G_1 = ctu_split(w, C, rho, -1.0 / (2.0 * h[f]), normals[f, 0, 0], normals[f, 0, 1],
                             normals[f, 1, 0], normals[f, 1, 1])
    for c in range(6):
        G[f, k, c] = G_0[c]
        G[f, k + 1, c] = G_1[c]
    return ok


# ---------------------------------------------------------------- interior faces
def interior_pass(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params, ctu, topo_L, topo_R,
                  flux, G):
    """Godunov flux of every interior face into flux (nf, nc) and, for ``ctu`` (2D), the
    transverse parts per unit Delta t of both sides' fluctuations into G (nf, 4, nc): side L's
    for its cell's two edges in G[:, 0:2], side R's in G[:, 2:4] (summed on the edges by a row
    gather, `parallel.matmul`: each face writes its own rows only). Returns the first face whose
    acoustic tensor is not positive definite, or -1."""
    return _interior_pass(N.shape[1])(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params,
                                      ctu, topo_L, topo_R, flux, G)


@kernel_factory
def _interior_pass(d):                  # a literal d: the (d, d) loops unrolled
    def interior_pass(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params,
                      ctu, topo_L, topo_R, flux, G):
        nc = d * d + d
        q_L, q_R, w_L, w_R = scratch((nc,)), scratch((nc,)), scratch((nc,)), scratch((nc,))
        F_L, F_R = scratch((3, 3)), scratch((3, 3))
        C_L, C_R = scratch((d, d, d, d)), scratch((d, d, d, d))
        t_L, t_R, t_s, v_s = scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,))
        for f in range(len(N)):
            rho_L = _gather(T_L, f, U, Q, rho, q_L, F_L, d)
            rho_R = _gather(T_R, f, U, Q, rho, q_R, F_R, d)
            m_L, m_R = cell_material[cell_L[f]], cell_material[cell_R[f]]
            if d == 1:                  # the law called, not inlined (`points.tangent_call`)
                tangent_call(laws[m_L], params[m_L], F_L, C_L, d)
                tangent_call(laws[m_R], params[m_R], F_R, C_R, d)
            else:
                tangent_point(laws[m_L], params[m_L], F_L, C_L, d)
                tangent_point(laws[m_R], params[m_R], F_R, C_R, d)
            if not riemann(q_L, C_L, rho_L, q_R, C_R, rho_R, N[f], t_L, t_R, t_s, v_s, d):
                return f
            for k in range(nc):
                flux[f, k] = 0.0
            add_normal_flux(t_s, v_s, N[f], 1.0, flux[f], d)
            if d == 2 and ctu:              # fluctuations A- dQ into L, A+ dQ into R, split at once
                fluctuations(q_L, q_R, N[f], t_L, t_R, flux[f], w_L, w_R, d)
                if not _split_into(w_L, C_L, rho_L, topo_L, f, G, 0):
                    return f
                if not _split_into(w_R, C_R, rho_R, topo_R, f, G, 2):
                    return f
        return -1
    return interior_pass


@njit(cache=True, nogil=True)
def boundary_edge_corrections(to_boundary, G, corr_bnd):
    """corr_bnd[j] += sum_k (G[part_k] - G[other_k]) for each boundary edge j, CSR rows
    ``to_boundary`` (indptr, parts, other parts): its ghost cell, a copy of the cell, sends back
    the opposite edge's part."""
    indptr, parts, other = to_boundary
    for j in range(len(indptr) - 1):
        for k in range(indptr[j], indptr[j + 1]):
            for c in range(G.shape[1]):
                corr_bnd[j, c] += G[parts[k], c] - G[other[k], c]


# ---------------------------------------------------------------- boundary faces
def boundary_sides(T, U, Q, rho, N, cell, cell_material, laws, params, t_L, v_L, Z, C, rho_f):
    """Interior side of every boundary face: traction t_L, velocity v_L (nf, d), impedance
    Z = sqrt(rho0 A_N) (nf, d, d), tangent C (nf, d, d, d, d) and density rho_f (nf,). Returns the
    first face whose acoustic tensor is not positive definite, or -1."""
    return _boundary_sides(N.shape[1])(T, U, Q, rho, N, cell, cell_material, laws, params, t_L, v_L, Z, C, rho_f)


@kernel_factory
def _boundary_sides(d):
    def boundary_sides(T, U, Q, rho, N, cell, cell_material, laws, params, t_L, v_L, Z, C, rho_f):
        dd, nc = d * d, d * d + d
        q, F, Zi = scratch((nc,)), scratch((3, 3)), scratch((d, d))
        for f in range(len(N)):
            rho_f[f] = _gather(T, f, U, Q, rho, q, F, d)
            m = cell_material[cell[f]]
            if d == 1:
                tangent_call(laws[m], params[m], F, C[f], d)
            else:
                tangent_point(laws[m], params[m], F, C[f], d)
            traction(q, N[f], t_L[f], d)
            for i in range(d):
                v_L[f, i] = q[dd + i]
            if not impedance(C[f], N[f], rho_f[f], Z[f], Zi, d):
                return f
        return -1
    return boundary_sides


def boundary_pass(N, t_L, v_L, t_s, v_s, C, rho_f, dt, ctu, topo, T_L, T_R, measure, flux, weight, R, corr_bnd):
    """Flux F_N(t*, v*) of every boundary face added to flux (nf, nc) (zero on entry) and, with
    ``ctu``, the transverse corrections of the fluctuation F_N(t*, v*) - F_N(t_L, v_L) entering
    the cell: an interior edge's integrated at once into R (through the interior traces T_L, T_R
    and face measures: few faces), weighted per node by ``weight`` ((step, inv_M) as in
    `_integrate`), a boundary edge's added to corr_bnd. Returns the first face whose acoustic
    tensor along an edge is not positive definite, or -1."""
    return _boundary_pass(N.shape[1])(N, t_L, v_L, t_s, v_s, C, rho_f, dt, ctu, topo, T_L, T_R, measure, flux,
                                      weight, R, corr_bnd)


@kernel_factory
def _boundary_pass(d):
    def boundary_pass(N, t_L, v_L, t_s, v_s, C, rho_f, dt, ctu, topo, T_L, T_R, measure, flux, weight, R, corr_bnd):
        w = scratch((d * d + d,))
        for f in range(len(N)):
            add_normal_flux(t_s[f], v_s[f], N[f], 1.0, flux[f], d)
            if d == 2 and ctu:              # the fluctuation F_N(t*, v*) - F_N(t_L, v_L) entering the cell
                for k in range(6):
                    w[k] = flux[f, k]
                add_normal_flux(t_L[f], v_L[f], N[f], -1.0, w, d)
                h, normals, edge_int, edge_bnd, sign = topo
                ok, G_0, G_1 = ctu_split(w, C[f], rho_f[f], -dt / (2.0 * h[f]), normals[0, f, 0], normals[0, f, 1],
                                         normals[1, f, 0], normals[1, f, 1])
                if not ok:
                    return f
                j = edge_int[0, f]
                if j >= 0:
                    _integrate(T_L, j, -sign[0, f] * measure[j], G_0, weight, R)
                    _integrate(T_R, j, sign[0, f] * measure[j], G_0, weight, R)
                j = edge_int[1, f]
                if j >= 0:
                    _integrate(T_L, j, -sign[1, f] * measure[j], G_1, weight, R)
                    _integrate(T_R, j, sign[1, f] * measure[j], G_1, weight, R)
                _add_boundary_edges(edge_bnd, f, G_0, G_1, corr_bnd)
        return -1
    return boundary_pass


def euler_update(gather, flux, corr, dt, volume, base, weight, out):
    """out = base + w (volume + G (flux + dt corr)) node by node: a forward Euler stage but its
    boundary terms in one pass over the nodes, given the volume term (n_dofs, nc), the interior
    faces' fluxes and corrections per unit Delta t (nf, nc) and w = step M^-1 given as
    ``weight`` = (step, inv_M (n_dofs,)).
    G (n_dofs, nf) is the interior surface integral as a gather (`DGMPM.gather_interior`): row i
    holds measure_f (T_R - T_L)[f, i] over the faces f of node i."""
    _euler_update(flux.shape[1])(gather, flux, corr, dt, volume, base, weight, out)


@kernel_factory
def _euler_update(nc):                  # a literal width: the loops unrolled
    def euler_update(gather, flux, corr, dt, volume, base, weight, out):
        indptr, indices, data = gather
        step, inv_M = weight
        r = scratch((nc,))
        for i in range(len(indptr) - 1):
            for c in range(nc):
                r[c] = volume[i, c]
            for k in range(indptr[i], indptr[i + 1]):
                f, g = indices[k], data[k]
                for c in range(nc):
                    r[c] += g * (flux[f, c] + dt * corr[f, c])
            for c in range(nc):
                out[i, c] = base[i, c] + (step * inv_M[i]) * r[c]
    return euler_update


@njit(cache=True, nogil=True)
def integrate_faces(T, measure, scale, flux, w, R):
    """R += w scale T^T (measure flux): the surface integral of face-constant fluxes (nf, nc), in
    face order, weighted per node by w = (step, inv_M) as in `_integrate`."""
    for f in range(len(measure)):
        _integrate(T, f, scale * measure[f], flux[f], w, R)
