"""The computed-torque controller's per-step arithmetic, compiled (numba): the same operations as
the numpy expressions they replace, in the same order, on the same BLAS and LAPACK.

Written with numpy, the controller's step after Pinocchio's model terms cost ~50 us in ~60 calls on
arrays of a few rows, nearly all of it numpy's per-call overhead. Here it is three calls. The
arithmetic is unchanged, so the results are too, bit for bit: elementwise operations are IEEE
operations in both (numba without fastmath contracts nothing into FMAs); products of matrices go
to BLAS's dgemm and dgemv, as numpy's ``@`` does; the Cholesky solve is LAPACK's dposv, called
through SciPy's Cython LAPACK (the library behind ``scipy.linalg.lapack``, which the numpy code
used). ``tests/unit/test_controller_model.py`` checks the kernels against the numpy expressions.

| kernel | what |
|---|---|
| ``gather`` | ``[M \\| c]`` in (base, arm) order from the upper triangle Pinocchio's CRBA fills, ``[J_m \\| a_0]``, ``J_b`` |
| ``schur`` | ``M*``, ``C*``, ``J_g``, ``a_drift`` (eqs. 3, 4, 7 and the drift; module doc of free_floating_arm) |
| ``pseudo_inverse`` | the damped pseudo-inverse and the null-space projector from an SVD |
| ``law`` | eqs. 6 and 8: the commanded acceleration, the torque clipped to the efforts, the task error |

The kernels are cached on disk by numba (``cache=True``): the first process compiles them (a few
seconds), the next ones load them.
"""

from __future__ import annotations

import llvmlite.binding as llvm
import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import get_cython_function_address, intrinsic

# LAPACK's dposv under a name of ours, resolved when numba links a kernel (compiled or loaded
# from its cache): no function pointer in the compiled code, so numba can cache it
_DPOSV = "zenorbit_dposv"
llvm.add_symbol(_DPOSV, get_cython_function_address("scipy.linalg.cython_lapack", "dposv"))


@intrinsic
def _dposv(typingctx, uplo, n, nrhs, a, lda, b, ldb, info):
    """LAPACK dposv on arrays (Fortran calling convention: every argument by pointer)."""

    def codegen(context, builder, signature, args):
        pointers = [
            builder.bitcast(context.make_array(kind)(context, builder, value).data, cgutils.voidptr_t)
            for kind, value in zip(signature.args, args)
        ]
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [cgutils.voidptr_t] * 8), _DPOSV
        )
        builder.call(function, pointers)
        return context.get_dummy_value()

    return types.void(uplo, n, nrhs, a, lda, b, ldb, info), codegen


@numba.njit(cache=True)
def gather(M, nle, J, a0, perm, base_v, arm_v):
    """(Mc, Ja, J_b): Mc = [M | c] with rows and columns in the order ``perm``, read from M's upper
    triangle (entry (i, j) is M[min, max] of the original indices); Ja = [J[:, arm_v] | a0];
    J_b = J[:, base_v]."""
    nv, n, nb = M.shape[0], arm_v.size, base_v.size
    Mc = np.empty((nv, nv + 1))
    for i in range(nv):
        for j in range(nv):
            a, b = perm[i], perm[j]
            Mc[i, j] = M[a, b] if a <= b else M[b, a]
        Mc[i, nv] = nle[perm[i]]
    Ja = np.empty((6, n + 1))
    J_b = np.empty((6, nb))
    for r in range(6):
        for j in range(n):
            Ja[r, j] = J[r, arm_v[j]]
        Ja[r, n] = a0[r]
        for j in range(nb):
            J_b[r, j] = J[r, base_v[j]]
    return Mc, Ja, J_b


@numba.njit(cache=True)
def schur(Mc, Ja, J_b, fixed):
    """(M*, C*, J_g, a_drift, LAPACK info) from gather's blocks (base block: J_b's columns).
    Free floating: X = M_bb^-1 [M_bm, c_b] (dposv), [M*, C*] = [M_mm, c_m] - M_bm^T X,
    [J_g, a_drift] = Ja - J_b X; ``fixed``: the arm's blocks as they are. M* symmetrized."""
    nv, nb = Mc.shape[0], J_b.shape[1]
    n = nv - nb
    if fixed:
        terms, task, info = Mc[nb:, nb:].copy(), Ja, 0
    else:
        a = np.asfortranarray(Mc[:nb, :nb])
        x = np.asfortranarray(Mc[:nb, nb:])
        uplo = np.full(1, 85, dtype=np.uint8)  # 'U'
        sizes = np.array([nb, n + 1, 0], dtype=np.int32)  # n, nrhs, info
        _dposv(uplo, sizes[0:1], sizes[1:2], a, sizes[0:1], x, sizes[0:1], sizes[2:3])
        info = sizes[2]
        x = np.ascontiguousarray(x)
        terms = Mc[nb:, nb:] - np.ascontiguousarray(Mc[:nb, nb:-1].T) @ x
        task = Ja - J_b @ x
    M_star = terms[:, :n]
    return 0.5 * (M_star + M_star.T), terms[:, n].copy(), task[:, :n].copy(), task[:, n].copy(), info


@numba.njit(cache=True)
def pseudo_inverse(U, s, Vt, lam2):
    """(V diag(s / (s^2 + lam2)) U^T, I - V V^T) from a thin SVD U diag(s) Vt (Fortran-ordered,
    as LAPACK's dgesdd returns them)."""
    inv = s / (s * s + lam2)
    V = np.ascontiguousarray(Vt.T)
    J_plus = V @ (np.expand_dims(inv, 1) * np.ascontiguousarray(U.T))
    N = np.eye(Vt.shape[1]) - V @ np.ascontiguousarray(Vt)
    return J_plus, N


@numba.njit(cache=True)
def law(
    U,
    s,
    Vt,
    lam2,
    p_d,
    p,
    rotation_error,
    v_d,
    w_d,
    a_d,
    dw_d,
    xdot,
    kp,
    kd,
    a_drift,
    null_kp,
    null_kd,
    q_posture,
    q,
    qd,
    M_star,
    C_star,
    effort,
):
    """(tau clipped to +-effort, the task error (p_d - p, rotation_error), qdd) of eqs. 6 and 8
    (ComputedTorqueLaw.control)."""
    error = np.concatenate((p_d - p, rotation_error))
    error_rate = np.concatenate((v_d, w_d)) - xdot
    xdd_r = np.concatenate((a_d, dw_d)) + kd * error_rate + kp * error
    J_plus, N = pseudo_inverse(U, s, Vt, lam2)
    qdd_0 = null_kp * (q_posture - q) - null_kd * qd
    qdd = J_plus @ (xdd_r - a_drift) + N @ qdd_0
    tau = M_star @ qdd + C_star
    return np.minimum(np.maximum(tau, -effort), effort), error, qdd
