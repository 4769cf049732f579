"""Compiled face passes of first-order DGMPM: one loop over a face set per right-hand side.

For every face the pass gathers the side states through the trace operators (CSR rows, summed
in scipy's order), evaluates each side's tangent with the law's point function
(`skdgmpm.materials.points`), solves the linearised Riemann problem (`skdgmpm.riemann` point
functions) and, for CTU, splits each fluctuation on the characteristic basis of the two edges of
the cell it enters as soon as it is known, adding those corrections to the edges' fluxes. The
corrections are proportional to Delta t (G = -dt / (2 h) B+ A dU): the interior pass stores them
per unit Delta t, so that a repeated attempt of the CFL guard reuses the whole pass; the boundary
pass (its stationary states depend on time) is redone, and `euler_update` adds
-int Phi (F* + dt G) to the residual as it advances the nodes.

Face-set arrays as in `skdgmpm.faces` ((nf, d) normals, (nf,) measures); a trace is the triple
(indptr, indices, data) of its CSR matrix; a CTU topology of one face side is
(h (nf,), normals (2, nf, 2), interior edge (2, nf), boundary edge (2, nf), sign (2, nf)) as built
by `DGMPM._setup_transverse` (empty arrays for DCU).
"""
from numba import njit

from skdgmpm.materials.points import tangent_point

from .faces import gather_row
from .kernel_cache import kernel_factory
from .riemann import _acoustic, _acoustic2, _godunov_flux2, _godunov_sides, _sqrt_spd, _sqrt_spd2, _stress_rate
from .system import scratch


@njit(cache=True)
def tangent_call(law, prm, F, C, d):
    """`skdgmpm.materials.points.tangent_point` as a function of its own, compiled once per d and
    called, where the compiled passes would otherwise inline every law at every call site: the 1D
    passes call it (their compile time halves), the 2D ones inline the law (its tangent stays in
    registers: the hot loops)."""
    tangent_point(law, prm, F, C, d)


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
def _edge_split(w, m, n0, n1, inv_rho, scale, Z):
    """scale B+_n w of one fluctuation w (6,) along the edge normal n = (n0, n1), as
    `riemann.transverse_positive`, returned as a 6-tuple; m = C : w_F and Z = (sqrt(rho A_n), its
    inverse) given (Z is shared by the two opposite edges of a cell, A_n being quadratic in n)."""
    z00, z01, z10, z11, i00, i01, i10, i11 = Z
    g0 = 0.0 + m[0] * n0 + m[1] * n1                     # g = (C : w_F) n
    g1 = 0.0 + m[2] * n0 + m[3] * n1
    a0 = 0.5 * ((i00 * g0 + i01 * g1) - w[4] * inv_rho)
    a1 = 0.5 * ((i10 * g0 + i11 * g1) - w[5] * inv_rho)
    return (scale * (a0 * n0), scale * (a0 * n1), scale * (a1 * n0), scale * (a1 * n1),
            scale * (-0.5 * g0 + 0.5 * (z00 * w[4] + z01 * w[5]) * inv_rho),
            scale * (-0.5 * g1 + 0.5 * (z10 * w[4] + z11 * w[5]) * inv_rho))


@njit(cache=True, inline="always")
def _impedance2(C, rho, n0, n1):
    """`riemann._sqrt_spd2` of rho A_n, A_n = C_iajb n_a n_b (2D): (ok, (Z, Z^-1) as an 8-tuple)."""
    ok, z00, z01, z10, z11, i00, i01, i10, i11 = _sqrt_spd2(
        rho * _acoustic2(C, 0, 0, n0, n1), rho * _acoustic2(C, 0, 1, n0, n1),
        rho * _acoustic2(C, 1, 0, n0, n1), rho * _acoustic2(C, 1, 1, n0, n1))
    return ok, (z00, z01, z10, z11, i00, i01, i10, i11)


@njit(cache=True, inline="always")
def _split(w, C, rho, scale, normals, f):
    """CTU [R18 eq 34-37] of the fluctuation w (6-tuple) entering a cell through face f:
    (ok, G_0, G_1), G_e = scale B+_n w for the cell's two edges e adjacent to the face (normals
    (2, nf, 2)) as 6-tuples (scalars: the whole split stays in registers); ok False where the
    acoustic tensor along an edge is not positive definite."""
    m = _stress_rate(w, C)              # C : w_F, shared by the two edges
    inv_rho = 1.0 / rho                 # one division (they dominate the cost)
    a0, a1 = normals[0, f, 0], normals[0, f, 1]
    b0, b1 = normals[1, f, 0], normals[1, f, 1]
    ok, Z = _impedance2(C, rho, a0, a1)
    if ok and not (b0 == -a0 and b1 == -a1):
        ok, Z_b = _impedance2(C, rho, b0, b1)
    else:
        Z_b = Z
    G_0 = _edge_split(w, m, a0, a1, inv_rho, scale, Z)
    G_1 = _edge_split(w, m, b0, b1, inv_rho, scale, Z_b)
    return ok, G_0, G_1


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
def _split_interior(w, C, rho, topo, f, corr, corr_bnd):
    """`_split` per unit Delta t (scale -1 / (2 h)): an interior edge j gets sign G_e added to
    corr[j], a boundary edge as `_add_boundary_edges`."""
    h, normals, edge_int, edge_bnd, sign = topo
    ok, G_0, G_1 = _split(w, C, rho, -1.0 / (2.0 * h[f]), normals, f)
    if not ok:
        return False
    j = edge_int[0, f]
    if j >= 0:
        s = sign[0, f]
        for k in range(6):
            corr[j, k] += s * G_0[k]
    j = edge_int[1, f]
    if j >= 0:
        s = sign[1, f]
        for k in range(6):
            corr[j, k] += s * G_1[k]
    _add_boundary_edges(edge_bnd, f, G_0, G_1, corr_bnd)
    return True


@njit(cache=True, inline="always")
def _face_flux(t_s, v_s, N, flux, d):
    """F_N = -[v* (x) N ; t*] of one face added to flux (nc,)."""
    for i in range(d):
        for a in range(d):
            flux[i * d + a] += -(v_s[i] * N[a])
        flux[d * d + i] += -t_s[i]


# ---------------------------------------------------------------- interior faces
def interior_pass(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params,
                  ctu, topo_L, topo_R, flux, corr, corr_bnd):
    """Godunov flux of every interior face into flux (nf, nc) and, for ``ctu`` (2D), the
    transverse corrections per unit Delta t of both sides' fluctuations added to corr (nf, nc)
    and corr_bnd (nb, nc) (zero on entry). Returns the first face whose acoustic tensor is not
    positive definite, or -1."""
    return _interior_pass(N.shape[1])(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params,
                                      ctu, topo_L, topo_R, flux, corr, corr_bnd)


@kernel_factory
def _interior_pass(d):                  # a literal d: the (d, d) loops unrolled
    def interior_pass(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params,
                      ctu, topo_L, topo_R, flux, corr, corr_bnd):
        nc = d * d + d
        q_L, q_R = scratch((nc,)), scratch((nc,))
        F_L, F_R = scratch((3, 3)), scratch((3, 3))
        C_L, C_R = scratch((d, d, d, d)), scratch((d, d, d, d))
        M, Z_L, Z_R, Zi, A = scratch((d, d)), scratch((d, d)), scratch((d, d)), scratch((d, d)), scratch((d, d))
        b, t_L, t_R, t_s, v_s = scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,))
        for f in range(len(N)):
            rho_L = _gather(T_L, f, U, Q, rho, q_L, F_L, d)
            rho_R = _gather(T_R, f, U, Q, rho, q_R, F_R, d)
            m_L, m_R = cell_material[cell_L[f]], cell_material[cell_R[f]]
            if d == 1:                  # the law called, not inlined: compile time (`tangent_call`)
                tangent_call(laws[m_L], params[m_L], F_L, C_L, d)
                tangent_call(laws[m_R], params[m_R], F_R, C_R, d)
            else:
                tangent_point(laws[m_L], params[m_L], F_L, C_L, d)
                tangent_point(laws[m_R], params[m_R], F_R, C_R, d)
            if d == 2:                      # the face in scalars (registers), its CTU split too
                n0, n1 = N[f, 0], N[f, 1]
                ok, ts0, ts1, vs0, vs1 = _godunov_flux2(q_L, C_L, rho_L, q_R, C_R, rho_R, n0, n1)
                if not ok:
                    return f
                flux[f, 0], flux[f, 1], flux[f, 2], flux[f, 3] = -(vs0 * n0), -(vs0 * n1), -(vs1 * n0), -(vs1 * n1)
                flux[f, 4], flux[f, 5] = -ts0, -ts1
                if ctu:                     # fluctuations A- dQ = F* - F_N(Q_L) into L, A+ dQ into R
                    tL0, tL1 = q_L[0] * n0 + q_L[1] * n1, q_L[2] * n0 + q_L[3] * n1
                    tR0, tR1 = q_R[0] * n0 + q_R[1] * n1, q_R[2] * n0 + q_R[3] * n1
                    w_L = (-(vs0 * n0) + q_L[4] * n0, -(vs0 * n1) + q_L[4] * n1, -(vs1 * n0) + q_L[5] * n0,
                           -(vs1 * n1) + q_L[5] * n1, -ts0 + tL0, -ts1 + tL1)
                    w_R = (-(q_R[4] * n0) + vs0 * n0, -(q_R[4] * n1) + vs0 * n1, -(q_R[5] * n0) + vs1 * n0,
                           -(q_R[5] * n1) + vs1 * n1, -tR0 + ts0, -tR1 + ts1)
                    if not _split_interior(w_L, C_L, rho_L, topo_L, f, corr, corr_bnd):
                        return f
                    if not _split_interior(w_R, C_R, rho_R, topo_R, f, corr, corr_bnd):
                        return f
                continue
            if not _godunov_sides(q_L, C_L, rho_L, q_R, C_R, rho_R, N[f], t_L, t_R, M, Z_L, Z_R, Zi, A, b, t_s, v_s, d):
                return f
            for k in range(nc):
                flux[f, k] = 0.0
            _face_flux(t_s, v_s, N[f], flux[f], d)
        return -1
    return interior_pass


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
        q, F, M, Zi = scratch((nc,)), scratch((3, 3)), scratch((d, d)), scratch((d, d))
        for f in range(len(N)):
            rho_f[f] = _gather(T, f, U, Q, rho, q, F, d)
            m = cell_material[cell[f]]
            if d == 1:
                tangent_call(laws[m], params[m], F, C[f], d)
            else:
                tangent_point(laws[m], params[m], F, C[f], d)
            for i in range(d):
                s = 0.0
                for a in range(d):
                    s += q[i * d + a] * N[f, a]
                t_L[f, i], v_L[f, i] = s, q[dd + i]
            _acoustic(C[f], N[f], rho_f[f], M, d)
            if not _sqrt_spd(M, Z[f], Zi, d):
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
        for f in range(len(N)):
            _face_flux(t_s[f], v_s[f], N[f], flux[f], d)
            if d == 2 and ctu:              # 2D: w = F_N(t*, v*) - F_N(t_L, v_L)
                n0, n1 = N[f, 0], N[f, 1]
                w = (flux[f, 0] + v_L[f, 0] * n0, flux[f, 1] + v_L[f, 0] * n1, flux[f, 2] + v_L[f, 1] * n0,
                     flux[f, 3] + v_L[f, 1] * n1, flux[f, 4] + t_L[f, 0], flux[f, 5] + t_L[f, 1])
                h, normals, edge_int, edge_bnd, sign = topo
                ok, G_0, G_1 = _split(w, C[f], rho_f[f], -dt / (2.0 * h[f]), normals, f)
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


@njit(cache=True)
def integrate_faces(T, measure, scale, flux, w, R):
    """R += w scale T^T (measure flux): the surface integral of face-constant fluxes (nf, nc), in
    face order, weighted per node by w = (step, inv_M) as in `_integrate`."""
    for f in range(len(measure)):
        _integrate(T, f, scale * measure[f], flux[f], w, R)
