"""Tridiagonal solve by parallel cyclic reduction held in vector registers (the general path's solve
for up to :data:`PCR_MAX_ROWS` unknowns).

A tridiagonal system ``a_i x_{i-1} + b_i x_i + c_i x_{i+1} = r_i`` is reduced level by level: at the
level of stride ``s`` every row eliminates its neighbours at ``i - s`` and ``i + s`` (Hockney's
parallel cyclic reduction),

    r'_i = r_i - alpha_i r_{i-s} - gamma_i r_{i+s},   alpha_i = a_i / b_{i-s},  gamma_i = c_i / b_{i+s},

which leaves a system of the same form coupling rows ``2 s`` apart. The coefficients ``alpha``,
``gamma`` and the final ``1 / b`` depend on the matrix only, so they are computed once per
factorisation (:func:`pcr_coefficients`); a solve applies the levels to the right-hand side only:
two multiply-adds per row and level, every row of a level independent of the others.

The reduction stops as soon as every remaining coupling is below ``2^-60`` of its diagonal (the
neglected terms are then below ``2^-60 max |x|``, far under the rounding of the result), and at the
latest when the stride reaches the number of rows (the system is then exactly diagonal). Our
matrices ``Cap/dt + K_theta`` are diagonally dominant M-matrices, for which the reduction is stable
without pivoting and the couplings shrink quadratically from level to level: the bundled example's
48 unknowns need 5 levels.

Why registers: the right-hand side of up to 64 rows fits in eight 8-wide vector registers, and a
level's shifted neighbours are lane rotations of adjacent registers (strides below 8) or whole
registers (strides of 8 or more). The solve is then ~35 vector instructions per level (6
registers for the example's 48 rows) with no loop, no memory round trip between levels and no long
dependency chain: twice as fast as the twisted scalar solve of :mod:`wallcal.engines.kernels` in a
stand-alone test of 21600 solves of 48 rows (1.2 against 2.4 ms), ~20 % off the general path's
run, where the passes around the solve overlap with it. numba's own
vectoriser cannot produce this (it vectorises loops, and a level written as a loop goes through
memory with misaligned reloads), so the solve is emitted as LLVM vector IR by a numba intrinsic,
one per register count (:data:`PCR_SOLVERS`). On processors without 512-bit vectors LLVM splits
the same IR into narrower instructions: same results, less gain.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types, uint64
from numba.extending import intrinsic

PCR_MAX_REGS = 8  # vector registers of 8 rows
PCR_MAX_ROWS = 8 * PCR_MAX_REGS
PCR_MAX_LEVELS = 6  # 2^6 = 64 = PCR_MAX_ROWS: exactly diagonal after 6 levels
PCR_TOL = 2.0**-60  # stop when every coupling is below this fraction of its diagonal

_DBL = ir.DoubleType()
_V8 = ir.VectorType(_DBL, 8)
_I64 = ir.IntType(64)
_MASK = ir.VectorType(ir.IntType(32), 8)


def levels_for(n_regs: int) -> int:
    """Levels after which a system of 8 n_regs rows is exactly diagonal (stride >= rows)."""
    levels, s = 0, 1
    while s < 8 * n_regs:
        s *= 2
        levels += 1
    return levels


class VectorIR:
    """Helpers that emit 8-wide float64 vector IR with an llvmlite builder."""

    FLAGS = ("contract",)

    def __init__(self, builder):
        self.b = builder
        self.zero = ir.Constant(_V8, [0.0] * 8)

    def ptr(self, p, off):
        a = self.b.gep(p, [ir.Constant(_I64, off)], inbounds=True)
        return self.b.bitcast(a, _V8.as_pointer())

    def load(self, p, off):
        """Elements off .. off + 7 of the float64 data pointer p."""
        return self.b.load(self.ptr(p, off), align=8)

    def store(self, v, p, off):
        self.b.store(v, self.ptr(p, off), align=8)

    def next_(self, regs, j, s):
        """Lane i: element 8 j + i + s of the sequence held in regs (zero beyond its end)."""
        if s % 8 == 0:
            q = j + s // 8
            return regs[q] if q < len(regs) else self.zero
        cur = regs[j]
        nxt = regs[j + 1] if j + 1 < len(regs) else self.zero
        return self.b.shuffle_vector(cur, nxt, ir.Constant(_MASK, [s + i for i in range(8)]))

    def prev_(self, regs, j, s):
        """Lane i: element 8 j + i - s of the sequence held in regs (zero before its start)."""
        if s % 8 == 0:
            q = j - s // 8
            return regs[q] if q >= 0 else self.zero
        prv = regs[j - 1] if j > 0 else self.zero
        return self.b.shuffle_vector(prv, regs[j], ir.Constant(_MASK, [8 - s + i for i in range(8)]))

    def sub(self, x, y):
        return self.b.fsub(x, y, flags=self.FLAGS)

    def mul(self, x, y):
        return self.b.fmul(x, y, flags=self.FLAGS)

    def reduce(self, regs, pal, pga, levels, max_levels):
        """The levels of the reduction (see the module docstring) applied to the right-hand side held
        in regs, with the per-level coefficients at the data pointers pal, pga (level-major, 8 len(regs)
        per level); ``levels`` (an i64 value) of the max_levels levels run. Returns the registers."""
        b = self.b
        n_regs = len(regs)
        R = list(regs)
        s = 1
        for lev in range(max_levels):
            entry = b.block
            do_level = b.append_basic_block(f"pcr_level{lev}")
            after = b.append_basic_block(f"pcr_after{lev}")
            b.cbranch(b.icmp_signed(">", levels, ir.Constant(levels.type, lev)), do_level, after)
            b.position_at_end(do_level)
            new = []
            for j in range(n_regs):
                base = lev * 8 * n_regs + 8 * j
                t = self.sub(R[j], self.mul(self.load(pal, base), self.prev_(R, j, s)))
                new.append(self.sub(t, self.mul(self.load(pga, base), self.next_(R, j, s))))
            done = b.block
            b.branch(after)
            b.position_at_end(after)
            merged = []
            for j in range(n_regs):
                phi = b.phi(_V8)
                phi.add_incoming(new[j], done)
                phi.add_incoming(R[j], entry)
                merged.append(phi)
            R = merged
            s *= 2
        return R


def data_pointers(context, builder, signature, args, n):
    """Data pointers of the first n (array) arguments of an intrinsic."""
    arrays = zip(signature.args[:n], args[:n], strict=True)
    return [context.make_array(ty)(context, builder, val).data for ty, val in arrays]


def _make_solver(n_regs: int):
    """numba intrinsic ``solve(r, al, ga, w, x, n_levels)`` for 8 n_regs rows (zero-padded beyond the
    system's m rows): x = w * (the right-hand side r after n_levels levels with the per-level
    coefficients al, ga, level-major with 8 n_regs per level). Arrays: contiguous float64."""
    max_levels = levels_for(n_regs)

    @intrinsic
    def solve(typingctx, r, al, ga, w, x, n_levels):
        sig = types.void(r, al, ga, w, x, n_levels)

        def codegen(context, builder, signature, args):
            pr, pal, pga, pw, px = data_pointers(context, builder, signature, args, 5)
            v = VectorIR(builder)
            R = v.reduce([v.load(pr, 8 * j) for j in range(n_regs)], pal, pga, args[5], max_levels)
            for j in range(n_regs):
                v.store(v.mul(v.load(pw, 8 * j), R[j]), px, 8 * j)
            return context.get_dummy_value()

        return sig, codegen

    return solve


PCR_SOLVERS = tuple(_make_solver(n) for n in range(1, PCR_MAX_REGS + 1))
_s1, _s2, _s3, _s4, _s5, _s6, _s7, _s8 = PCR_SOLVERS


@njit(cache=True)
def pcr_solve(n_regs, r, al, ga, w, x, n_levels):
    """x = A^-1 r by the reduction of :func:`pcr_coefficients` (r and x: 8 n_regs rows, zero-padded;
    x may be a view of the first m rows of a longer buffer: all 8 n_regs rows are written, zeros
    beyond m)."""
    if n_regs <= 4:
        if n_regs == 1:
            _s1(r, al, ga, w, x, n_levels)
        elif n_regs == 2:
            _s2(r, al, ga, w, x, n_levels)
        elif n_regs == 3:
            _s3(r, al, ga, w, x, n_levels)
        else:
            _s4(r, al, ga, w, x, n_levels)
    elif n_regs == 5:
        _s5(r, al, ga, w, x, n_levels)
    elif n_regs == 6:
        _s6(r, al, ga, w, x, n_levels)
    elif n_regs == 7:
        _s7(r, al, ga, w, x, n_levels)
    else:
        _s8(r, al, ga, w, x, n_levels)


PCR_WORK_PAD = 8 * PCR_MAX_REGS  # zero margins of the work rows (>= the largest stride)


@njit(cache=True)
def pcr_work(m):
    """Work array of :func:`pcr_coefficients` for m rows: zero margins, unit diagonal in them."""
    work = np.zeros((7, m + 2 * PCR_WORK_PAD))
    for i in range(work.shape[1]):
        work[1, i] = 1.0
        work[6, i] = 1.0
    return work


@njit(cache=True, error_model="numpy")
def pcr_coefficients(diag, off, m, n_regs, al, ga, w, work):
    """Coefficients of the reduction of the symmetric tridiagonal matrix with diagonal ``diag[:m]``
    and off-diagonal ``off[i]`` between rows i and i + 1: per level (level-major, 8 n_regs per
    level) ``al = alpha``, ``ga = gamma``, and ``w = 1 / b`` of the final diagonal system. Returns the
    number of levels. al, ga and w must be zero beyond row m (as allocated: rows beyond m are never
    written; levels beyond the returned number are left as they were). work: :func:`pcr_work` for
    m rows (its margins are never written).

    A lambda(T) run refactorises a few hundred times, so this is written for speed: the rows live
    between zero margins (unit diagonal) wider than any stride, so that every level is one
    branch-free, vectorised pass (the couplings of row i to rows beyond the ends are zero by
    construction), with one division per row and level (the reciprocals of the diagonal) and none
    in the stopping test. numpy's error model (no zero-division check, whose branch would keep the
    division pass scalar): the diagonal of an M-matrix never vanishes."""
    n = 8 * n_regs
    P = PCR_WORK_PAD
    a = work[0]
    b = work[1]
    c = work[2]
    na = work[3]
    nb = work[4]
    nc = work[5]
    rb = work[6]
    a[P] = 0.0
    c[P + m - 1] = 0.0
    for i in range(m):
        b[P + i] = diag[i]
    for i in range(m - 1):
        c[P + i] = off[i]
        a[P + i + 1] = off[i]
    levels = 0
    s = 1
    while True:
        for i in range(m):
            rb[uint64(P + i)] = 1.0 / b[uint64(P + i)]
        n_coupled = 0  # rows whose couplings are not yet negligible
        for i in range(m):
            k = uint64(P + i)
            n_coupled += 1 if abs(a[k]) + abs(c[k]) >= PCR_TOL * abs(b[k]) else 0
        if n_coupled == 0 or s >= m:
            break
        base = levels * n
        # one pass per array written (few arrays per pass: LLVM vectorises them), then the new
        # couplings and diagonal take the old ones' places
        for i in range(m):
            k = uint64(P + i)
            al[uint64(base + i)] = a[k] * rb[uint64(P + i - s)]
        for i in range(m):
            k = uint64(P + i)
            ga[uint64(base + i)] = c[k] * rb[uint64(P + i + s)]
        for i in range(m):
            k = uint64(P + i)
            nb[k] = b[k] - al[uint64(base + i)] * c[uint64(P + i - s)] - ga[uint64(base + i)] * a[uint64(P + i + s)]
        for i in range(m):
            na[uint64(P + i)] = -al[uint64(base + i)] * a[uint64(P + i - s)]
        for i in range(m):
            nc[uint64(P + i)] = -ga[uint64(base + i)] * c[uint64(P + i + s)]
        a, na = na, a
        b, nb = nb, b
        c, nc = nc, c
        levels += 1
        s *= 2
    for i in range(m):
        w[i] = rb[uint64(P + i)]
    return levels


def solve_reference(diag: np.ndarray, off: np.ndarray, r: np.ndarray) -> np.ndarray:
    """x = A^-1 r through :func:`pcr_coefficients` and :func:`pcr_solve` (tests and checks; m <= 64)."""
    m = diag.shape[0]
    n_regs = max((m + 7) // 8, 1)
    n = 8 * n_regs
    al = np.zeros(PCR_MAX_LEVELS * n)
    ga = np.zeros(PCR_MAX_LEVELS * n)
    w = np.zeros(n)
    levels = pcr_coefficients(diag, off, m, n_regs, al, ga, w, pcr_work(m))
    rp = np.zeros(n)
    rp[:m] = r
    x = np.zeros(n)
    pcr_solve(n_regs, rp, al, ga, w, x, levels)
    return x[:m]
