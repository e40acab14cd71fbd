"""Initial guesses for a graph: the file's vertices, odometry chaining along a spanning tree,
and the chordal relaxation (2D below; 3D in :func:`_chordal_3d`).

* **Spanning tree** (:func:`spanning_tree_initialization`): a minimum spanning tree of the
  relative-pose edges in which consecutive ids (``|i - j| = 1``, odometry) cost 1 and every
  other edge 2, so the tree is the odometry chain wherever one exists and loop closures only
  bridge its gaps. Poses are composed outwards from the fixed pose(s) in breadth-first order:
  for a tree edge ``i → j`` with measurement ``Z``, ``X_j = X_i ⊕ Z`` (or ``X_i = X_j ⊕ Z⁻¹``
  when the child is ``i``).
* **Chordal relaxation** (:func:`chordal_initialization`), with SE-Sync's weights
  ``κ = Ω_θθ`` and ``τ = 2 / tr(Ω_tt⁻¹)``. Rotations first: with ``z_i = cos θ_i + i sin θ_i``
  relaxed to any complex number, ``min Σ κ |z_j - z_i e^{iθ̃}|²`` is linear least squares
  (``|z_j - z_i w|² = ½ ‖R_j - R_i R̃‖²_F`` for unit ``z``); the solution is projected back
  to ``θ_i = atan2(Im z_i, Re z_i)``. Then translations, linear given the rotations:
  ``min Σ τ ‖t_j - t_i - R_i t̃‖²``, a weighted graph Laplacian solved once for ``x`` and
  ``y``. The fixed poses keep their values in both steps.

Landmarks without vertices start from their first ``se2_xy`` or ``range_bearing`` reading;
landmarks seen only by bearings are triangulated (linear least squares over the bearing lines)
and those seen only by ranges are multilaterated (linear least squares after subtracting the
mean range equation).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from slamkit.errors import ConfigError, GeometryError
from slamkit.optim import factors3d
from slamkit.optim.data import FloatArray, GraphData
from slamkit.optim.graph import GraphProblem, sesync_row_weights
from slamkit.optim.sparse import LinearSolverName, solve_spd

__all__ = [
    "chordal_initialization",
    "initial_values",
    "spanning_tree_initialization",
]


def _pose_edges(problem: GraphProblem) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray]:
    """Rows ``a``, ``b``, measurements (internal format) and information of every
    relative-pose edge."""
    a_l, b_l, z_l, w_l = [], [], [], []
    for blk in problem.blocks:
        if blk.kind in ("se2", "se3"):
            assert blk.b is not None
            a_l.append(blk.a)
            b_l.append(blk.b)
            z_l.append(blk.measurement)
            w_l.append(blk.edges.information)
    if not a_l:
        m, r = (3, 3) if problem.dim == 2 else (12, 6)
        return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, m)), np.zeros((0, r, r)))
    return np.concatenate(a_l), np.concatenate(b_l), np.concatenate(z_l), np.concatenate(w_l)


def _anchor_values(problem: GraphProblem) -> tuple[np.ndarray, FloatArray]:
    """Rows whose values are known before chaining, and the starting poses (internal format).

    The file's vertex values when it has vertices (fixed rows anchor), else the origin for
    the anchored first pose, or the measurement of the first prior.
    """
    n = problem.pose_ids.shape[0]
    data = problem.data
    if data.poses.shape[0]:
        poses = problem.to_internal(data.poses.copy())
    elif problem.dim == 2:
        poses = np.zeros((n, 3))
    else:
        poses = np.tile(np.concatenate([np.zeros(3), np.eye(3).ravel()]), (n, 1))
    known = problem.fixed.copy()
    if not known.any():
        for blk in problem.blocks:
            if blk.kind in ("se2_prior", "se3_prior") and len(blk.edges):
                row = int(blk.a[0])
                poses[row] = blk.measurement[0]
                known[row] = True
                break
    if not known.any():
        known[problem.alias[0]] = True
    return known, poses


def _child_pose(parent: FloatArray, z: FloatArray, forward: bool) -> FloatArray:
    """``X_parent ⊕ Z`` (``forward``) or ``X_parent ⊕ Z⁻¹``, one internal-format row."""
    if parent.shape[0] == 3:  # SE(2): Z⁻¹ = (-R_zᵀ t_z, -θ_z)
        x, y, th = parent
        zx, zy, zt = z
        if not forward:
            cz, sz = np.cos(zt), np.sin(zt)
            zx, zy, zt = -(cz * zx + sz * zy), -(-sz * zx + cz * zy), -zt
        c, s = np.cos(th), np.sin(th)
        return np.array([x + c * zx - s * zy, y + s * zx + c * zy, th + zt])
    Rp, Rz = parent[3:].reshape(3, 3), z[3:].reshape(3, 3)
    if forward:  # (t_p + R_p t_z, R_p R_z)
        return np.concatenate([parent[:3] + Rp @ z[:3], (Rp @ Rz).ravel()])
    # Z⁻¹ = (-R_zᵀ t_z, R_zᵀ)
    return np.concatenate([parent[:3] - Rp @ (Rz.T @ z[:3]), (Rp @ Rz.T).ravel()])


def spanning_tree_initialization(problem: GraphProblem) -> FloatArray:
    """Poses (file format) chained along a spanning tree that prefers odometry edges."""
    known, poses = _anchor_values(problem)
    a, b, z, _ = _pose_edges(problem)
    n = poses.shape[0]
    if a.shape[0] == 0:
        return problem.to_external(poses)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    _, first = np.unique(key, return_index=True)  # one edge per pair of poses
    ids = problem.pose_ids
    weight = np.where(np.abs(ids[a[first]] - ids[b[first]]) == 1, 1.0, 2.0)
    # A virtual root joined to every known pose makes one tree grow from all anchors.
    root = n
    k_rows = np.flatnonzero(known)
    rows = np.concatenate([lo[first], np.full(k_rows.shape[0], root)])
    cols = np.concatenate([hi[first], k_rows])
    w = np.concatenate([weight, np.full(k_rows.shape[0], 0.5)])
    graph = scipy.sparse.coo_matrix((w, (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    tree = scipy.sparse.csgraph.minimum_spanning_tree(graph)
    order, pred = scipy.sparse.csgraph.breadth_first_order(tree, root, directed=False)
    # Edge index of each (parent, child) pair, looked up by its key.
    sorted_key = key[first]
    out = poses.copy()
    za = z[first]
    af = a[first]
    for child in order[1:].tolist():
        parent = int(pred[child])
        if parent == root:
            continue  # an anchor: keeps its value
        e = int(np.searchsorted(sorted_key, min(parent, child) * n + max(parent, child)))
        out[child] = _child_pose(out[parent], za[e], forward=bool(af[e] == parent))
    if problem.dim == 2:
        out[:, 2] = np.arctan2(np.sin(out[:, 2]), np.cos(out[:, 2]))
    return problem.to_external(out[problem.alias])


def chordal_initialization(
    problem: GraphProblem, linear_solver: LinearSolverName = "auto"
) -> FloatArray:
    """Poses (file format) from the chordal relaxation (rotations, projection, translations)."""
    if problem.dim == 3:
        return _chordal_3d(problem, linear_solver)
    known, poses = _anchor_values(problem)
    a, b, z, info = _pose_edges(problem)
    n = poses.shape[0]
    if a.shape[0] == 0:
        return poses
    w = sesync_row_weights(info)
    kappa, tau = 0.5 * w[:, 0] ** 2, w[:, 2] ** 2
    # Aliased rows (EQUIV) are merged into their representative before solving.
    a, b = problem.alias[a], problem.alias[b]
    free = ~known & (problem.alias == np.arange(n))
    idx = np.cumsum(free) - 1

    # --- rotations: unknowns (Re z, Im z) per free pose; residual z_j - W z_i, W = R(θ̃).
    cw, sw = np.cos(z[:, 2]), np.sin(z[:, 2])
    W = np.stack([np.stack([cw, -sw], -1), np.stack([sw, cw], -1)], -2)  # (E, 2, 2)
    zc = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], -1)
    Ji = -W
    Jj = np.broadcast_to(np.eye(2), W.shape)
    rot = _linear_solve(
        n, a, b, Ji, Jj, kappa, np.zeros((a.shape[0], 2)), zc, free, idx, 2, linear_solver
    )
    theta = poses[:, 2].copy()
    theta[free] = np.arctan2(rot[free, 1], rot[free, 0])
    theta = theta[problem.alias]

    # --- translations: residual t_j - t_i - R_i t̃ given the rotations.
    ci, si = np.cos(theta[a]), np.sin(theta[a])
    rt = np.stack([ci * z[:, 0] - si * z[:, 1], si * z[:, 0] + ci * z[:, 1]], -1)
    eye = np.broadcast_to(np.eye(2), W.shape)
    trans = _linear_solve(n, a, b, -eye, eye, tau, rt, poses[:, :2], free, idx, 2, linear_solver)
    out = poses.copy()
    out[free, :2] = trans[free]
    out[:, 2] = theta
    return out[problem.alias]


def _chordal_3d(problem: GraphProblem, linear_solver: LinearSolverName) -> FloatArray:
    """3D chordal relaxation: each row ``x`` of the rotations solves ``min Σ κ ‖x_j - x_i R̃‖²``
    (row ``k`` of ``R_j - R_i R̃``); the stacked rows are projected to SO(3) by SVD
    (``R = U diag(1, 1, det(U Vᵀ)) Vᵀ``); then ``min Σ τ ‖t_j - t_i - R_i t̃‖²``."""
    known, poses = _anchor_values(problem)
    a, b, z, info = _pose_edges(problem)
    n = poses.shape[0]
    if a.shape[0] == 0:
        return problem.to_external(poses)
    w = factors3d.sesync_row_weights_3d(info)
    kappa, tau = w[:, 0] ** 2, w[:, 9] ** 2
    a, b = problem.alias[a], problem.alias[b]
    free = ~known & (problem.alias == np.arange(n))
    idx = np.cumsum(free) - 1
    Rz = z[:, 3:].reshape(-1, 3, 3)
    R0 = poses[:, 3:].reshape(-1, 3, 3)
    eye = np.broadcast_to(np.eye(3), Rz.shape)
    zero = np.zeros((a.shape[0], 3))
    rows = [
        # residual x_jᵀ - R̃ᵀ x_iᵀ for the row vector x = row k of R
        _linear_solve(
            n,
            a,
            b,
            -np.swapaxes(Rz, 1, 2),
            eye,
            kappa,
            zero,
            R0[:, k, :],
            free,
            idx,
            3,
            linear_solver,
        )
        for k in range(3)
    ]
    M = np.stack(rows, axis=1)  # (n, 3, 3): row k of every relaxed rotation
    U, _, Vt = np.linalg.svd(M)
    det = np.linalg.det(U @ Vt)
    D = np.broadcast_to(np.eye(3), M.shape).copy()
    D[:, 2, 2] = det
    R = U @ D @ Vt
    R[~free] = R0[~free]
    R = R[problem.alias]
    rt = np.einsum("eij,ej->ei", R[a], z[:, :3])
    trans = _linear_solve(n, a, b, -eye, eye, tau, rt, poses[:, :3], free, idx, 3, linear_solver)
    out = poses.copy()
    out[free, :3] = trans[free]
    out[:, 3:] = R.reshape(-1, 9)
    return problem.to_external(out[problem.alias])


def _linear_solve(
    n: int,
    a: np.ndarray,
    b: np.ndarray,
    Ja: FloatArray,
    Jb: FloatArray,
    weight: FloatArray,
    offset: FloatArray,
    known_values: FloatArray,
    free: np.ndarray,
    idx: np.ndarray,
    d: int,
    linear_solver: LinearSolverName,
) -> FloatArray:
    """``min Σ w ‖Ja x_a + Jb x_b - offset‖²`` over the free rows (``d`` unknowns per row).

    Known rows keep ``known_values``; returns all rows ``(n, d)``.
    """
    nf = int(free.sum())
    if nf == 0:
        return known_values.copy()
    # The residual with known rows moved to the right-hand side: c = offset - J_known x_known.
    c = offset.copy()
    for rows, J in ((a, Ja), (b, Jb)):
        kn = ~free[rows]
        c[kn] -= np.einsum("eij,ej->ei", J[kn], known_values[rows[kn]])
    blocks_r, blocks_c, blocks_v = [], [], []
    rhs = np.zeros(nf * d)
    pairs = ((a, Ja), (b, Jb))
    for ra, JA in pairs:
        fa = free[ra]
        g = np.einsum("e,eji,ej->ei", weight, JA, c)[fa]
        np.add.at(rhs, (d * idx[ra[fa]])[:, None] + np.arange(d), g)
        for rb, JB in pairs:
            m = fa & free[rb]
            blk = np.einsum("e,eki,ekj->eij", weight, JA, JB)[m]
            r0 = (d * idx[ra[m]])[:, None, None] + np.arange(d)[None, :, None]
            c0 = (d * idx[rb[m]])[:, None, None] + np.arange(d)[None, None, :]
            r0, c0 = np.broadcast_arrays(r0, c0)
            blocks_r.append(r0.ravel())
            blocks_c.append(c0.ravel())
            blocks_v.append(blk.ravel())
    H = scipy.sparse.coo_matrix(
        (np.concatenate(blocks_v), (np.concatenate(blocks_r), np.concatenate(blocks_c))),
        shape=(nf * d, nf * d),
    ).tocsc()
    try:
        x = solve_spd(H, rhs, linear_solver)
    except Exception as exc:  # SingularSystem and back-end errors
        raise GeometryError(
            f"chordal initialisation: the linear system is singular ({exc})"
        ) from None
    out = known_values.copy()
    out[free] = x.reshape(-1, d)
    return out


def _initial_landmarks(problem: GraphProblem, poses: FloatArray) -> FloatArray:
    """Landmarks ``(L, 2)``: the file's vertices, else from the readings (module docstring)."""
    data = problem.data
    n_l = problem.landmark_ids.shape[0]
    if data.landmarks.shape[0]:
        return data.landmarks.copy()
    out = np.full((n_l, 2), np.nan)
    # Bearing lines n·(l - t) = 0 and range equations, accumulated per landmark.
    A = np.zeros((n_l, 2, 2))
    rhs = np.zeros((n_l, 2))
    r_sum = np.zeros(n_l)
    r_cnt = np.zeros(n_l)
    p_sum = np.zeros((n_l, 2))
    q_sum = np.zeros(n_l)
    range_rows = []
    for blk in problem.blocks:
        if blk.b is None or not blk.b_is_landmark:
            continue
        x = poses[blk.a]
        zm = blk.edges.measurement
        c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
        if blk.kind in ("se2_xy", "range_bearing"):
            if blk.kind == "se2_xy":
                px, py = zm[:, 0], zm[:, 1]
            else:
                px, py = zm[:, 0] * np.cos(zm[:, 1]), zm[:, 0] * np.sin(zm[:, 1])
            world = np.stack([x[:, 0] + c * px - s * py, x[:, 1] + s * px + c * py], -1)
            # The first reading wins: write in reverse order so earlier rows overwrite later.
            unset = np.isnan(out[blk.b[::-1], 0])
            out[blk.b[::-1][unset]] = world[::-1][unset]
        elif blk.kind == "bearing":
            phi = x[:, 2] + zm[:, 0]
            nrm = np.stack([-np.sin(phi), np.cos(phi)], -1)
            np.add.at(A, blk.b, nrm[:, :, None] * nrm[:, None, :])
            np.add.at(rhs, blk.b, nrm * np.einsum("ei,ei->e", nrm, x[:, :2])[:, None])
        else:  # range: ‖l‖² - 2 tᵀl + ‖t‖² = r²
            range_rows.append((blk.b, x[:, :2], zm[:, 0]))
            np.add.at(r_cnt, blk.b, 1.0)
            np.add.at(p_sum, blk.b, x[:, :2])
            np.add.at(q_sum, blk.b, np.einsum("ei,ei->e", x[:, :2], x[:, :2]) - zm[:, 0] ** 2)
            np.add.at(r_sum, blk.b, 1.0)
    # Ranges: subtracting the mean equation removes ‖l‖²: -2 (t - t̄)ᵀ l = (r² - ‖t‖²) - mean.
    if range_rows:
        cnt = np.maximum(r_cnt, 1.0)
        t_bar = p_sum / cnt[:, None]
        q_bar = q_sum / cnt
        for rows, t, r in range_rows:
            u = -2.0 * (t - t_bar[rows])
            v = -(np.einsum("ei,ei->e", t, t) - r**2 - q_bar[rows])
            np.add.at(A, rows, u[:, :, None] * u[:, None, :])
            np.add.at(rhs, rows, u * v[:, None])
    todo = np.isnan(out[:, 0])
    if todo.any():
        det = np.linalg.det(A[todo])
        ok = np.abs(det) > 1e-12 * np.maximum(np.abs(A[todo]).max(axis=(1, 2)) ** 2, 1e-300)
        if not ok.all():
            bad = int(problem.landmark_ids[np.flatnonzero(todo)[np.flatnonzero(~ok)[0]]])
            raise GeometryError(
                f"landmark {bad}: its readings do not determine a starting position "
                "(give it a vertex or more readings)"
            )
        out[todo] = np.linalg.solve(A[todo], rhs[todo][:, :, None])[:, :, 0]
    return out


def initial_values(
    problem: GraphProblem, method: str = "auto", linear_solver: LinearSolverName = "auto"
) -> tuple[FloatArray, FloatArray]:
    """Starting ``(poses, landmarks)`` for ``problem``.

    ``method``: ``"vertices"`` (the file's values; an error when it has none), ``"odometry"``
    (:func:`spanning_tree_initialization`), ``"chordal"`` (:func:`chordal_initialization`),
    or ``"auto"`` (vertices when the file has them, else odometry). :func:`~slamkit.optim.optimize`
    resolves its own ``"auto"`` first and picks the grown-prefix start for landmark graphs
    without vertices (:func:`~slamkit.optim.solvers.resolve_initialization`; that start runs
    the optimiser, so it lives in :mod:`slamkit.optim.solvers`).
    """
    data: GraphData = problem.data
    has_vertices = data.poses.shape[0] > 0
    if method == "auto":
        method = "vertices" if has_vertices else "odometry"
    if method == "vertices":
        if not has_vertices:
            raise GeometryError(
                "initialization 'vertices': the graph has no vertex values; use 'odometry' "
                "or 'chordal'"
            )
        poses = data.poses.copy()[problem.alias]
    elif method == "odometry":
        poses = spanning_tree_initialization(problem)
    elif method == "chordal":
        poses = chordal_initialization(problem, linear_solver)
    else:
        raise ConfigError(f"initialization: unknown method {method!r}")
    return poses, _initial_landmarks(problem, poses)
