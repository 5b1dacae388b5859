"""Block-tridiagonal factor of the (r, z) solver's matrix, and the caches that share factors.

:class:`BlockTridiagonal` is the direct solver of ``(C / tau + K) x = b``
(:mod:`firmware_sim.rz.solver`): block elimination with the Schur complements'
inverses kept dense.  Two caches spare the elimination's cost (an inverse per
block row), both keyed by the exact bytes that determine what they hold:

* whole factors (:func:`firmware_sim.rz.solver._factor`): a world rebuilt for the same
  probe, scene and step reuses its factor;
* leading block rows (:data:`_ROW_CACHE`): row ``j``'s inverse depends only on the
  rows up to ``j``, and the probe's rows come first in every contact configuration
  of a probe, so a factor on a new object takes the probe's rows and eliminates
  its object's -- the same arithmetic on the same numbers, so the same bits (in
  air the probe's rows are narrower: nothing to share there).  A factor keeps and takes
  only the rows it is told others can share (``shared_rows``: the probe's, above its
  object), so the cache holds those and not the object rows no other matrix has.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict

import numpy as np

__all__ = ["BlockTridiagonal", "clear_row_cache"]

#: Inverses of leading block rows, keyed by a digest of everything they depend on (the rows up to
#: theirs, as far as coupled), least recently used dropped first.  A probe's rows (substrate,
#: heater, sensing layer: the first 72 of the paper probe's 121 on an object, 44 unknowns wide) are
#: shared by its configurations on every object at the same step; an object's rows (75 wide) are
#: most of a factor's cost, so a new object's factor costs ~80 % of a fresh one.
_ROW_CACHE: OrderedDict[bytes, np.ndarray] = OrderedDict()
_ROW_CACHE_BYTES = 32 * 2**20
_ROW_LOCK = threading.Lock()
_row_bytes = 0


def clear_row_cache() -> None:
    """Forget the shared block-row inverses (with the factors: a cold start)."""
    global _row_bytes
    with _ROW_LOCK:
        _ROW_CACHE.clear()
        _row_bytes = 0


def _cached_row(key: bytes) -> np.ndarray | None:
    with _ROW_LOCK:
        G = _ROW_CACHE.get(key)
        if G is not None:
            _ROW_CACHE.move_to_end(key)
        return G


def _keep_row(key: bytes, G: np.ndarray) -> None:
    global _row_bytes
    G.flags.writeable = False     # shared by every factor that has this row
    with _ROW_LOCK:
        if key in _ROW_CACHE:
            return
        _ROW_CACHE[key] = G
        _row_bytes += G.nbytes
        while _row_bytes > _ROW_CACHE_BYTES and len(_ROW_CACHE) > 1:
            _, old = _ROW_CACHE.popitem(last=False)
            _row_bytes -= old.nbytes


#: Widths above which a block's inverse is taken in two halves (:func:`_inverse`).
_SPLIT_WIDTH = 48

try:
    # The gufunc behind ``np.linalg.inv`` (the same LAPACK call on the same numbers, so the same
    # bits), called directly: the wrapper's checks and conversions cost ~10 % of a 47-wide inverse,
    # and a factor takes two per block row.  :func:`_inverse` sets the same error state once.
    from numpy.linalg import _umath_linalg

    def _inv(a: np.ndarray) -> np.ndarray:
        return _umath_linalg.inv(a, signature="d->d")
except ImportError:  # pragma: no cover - a NumPy without the private module
    _inv = np.linalg.inv


def _singular(err: str, flag: int) -> None:
    raise np.linalg.LinAlgError("Singular matrix")


# The error state ``np.linalg.inv`` sets around its gufunc (a singular block raises), once per block
# (as a decorator: a fresh state per call, so threads factoring at once do not share one).
@np.errstate(call=_singular, invalid="call", over="ignore", divide="ignore", under="ignore")
def _inverse(S: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive definite block, in two halves when it is wide.

    ``S = [[A, B], [B^T, D]]``: ``S^-1 = [[A^-1 + X B^T A^-1, X], [X^T, C^-1]]`` with the Schur
    complement ``C = D - B^T A^-1 B`` (positive definite too, so no pivoting is needed) and
    ``X = -A^-1 B C^-1``.  LAPACK's inverse of a 75-wide block costs as much as fifteen of its
    matrix products here; two half-width inverses and four products cost 30-45 % less on the
    75- and 95-wide blocks (one thread), the same to round-off.  A singular block raises
    ``LinAlgError``, as ``np.linalg.inv`` would.
    """
    n = S.shape[0]
    if n <= _SPLIT_WIDTH:
        return _inv(S)
    k = n // 2
    Ai = _inv(S[:k, :k])
    B = S[:k, k:]
    AiB = Ai @ B
    Ci = _inv(S[k:, k:] - B.T @ AiB)
    X = -(AiB @ Ci)
    out = np.empty_like(S)
    out[:k, :k] = Ai - X @ AiB.T
    out[:k, k:] = X
    out[k:, :k] = X.T
    out[k:, k:] = Ci
    return out


class BlockTridiagonal:
    """Factor of a symmetric block-tridiagonal matrix with diagonal off-diagonal blocks.

    ``A = tridiag(diag(b_j), D_j, diag(b_{j+1}))``: ``D_j`` (m x m, here
    tridiagonal) the couplings inside a block row, ``b_j`` (m,) the coupling
    between block rows ``j-1`` and ``j``.  Block elimination
    ``S_0 = D_0, S_j = D_j - diag(b_j) S_{j-1}^{-1} diag(b_j)``; the inverses
    ``G_j = S_j^{-1}`` are kept dense, so a solve is two sweeps of one
    mat-vec per block row (:meth:`_plan`).  The matrix is symmetrically scaled to a unit
    diagonal first, which keeps the explicit inverses accurate when the
    conductances span many decades (foam to aluminium, micrometre to
    centimetre cells).

    Parameters
    ----------
    diag : ndarray, (n, m)
        Main diagonal.
    off_in : ndarray, (n, m - 1)
        Off-diagonal inside each block (entry ``[j, i]`` couples i, i+1).
    off_between : ndarray, (n - 1, m)
        Coupling between block rows j and j+1 (entry ``[j, i]``).
    shared_rows : int, optional
        How many leading block rows another factor may share (:data:`_ROW_CACHE`): those are
        taken from it and kept in it; the rest are eliminated here only.  Default: every row.
        A hint that spends the cache on the rows other matrices have (the probe's, above any
        object); the factor is the same whatever it says.
    """

    def __init__(self, diag: np.ndarray, off_in: np.ndarray, off_between: np.ndarray,
                 shared_rows: int | None = None) -> None:
        n, m = diag.shape
        if np.any(diag <= 0):
            raise ValueError("matrix diagonal must be positive (SPD system)")
        s = 1.0 / np.sqrt(diag)
        self.scale = s
        a_in = off_in * s[:, :-1] * s[:, 1:]
        b = off_between * s[:-1] * s[1:]
        # Unknowns past the last coupled one of a block row (the grid's inactive cells beyond a
        # layer's radius: no coupling at all) are their own solution, x = rhs / diag; the dense
        # work is kept to the leading coupled part of each block (often half the grid's width,
        # or none at all), which the block elimination sees unchanged.
        coupled = np.zeros((n, m), dtype=bool)
        coupled[:, :-1] |= a_in != 0
        coupled[:, 1:] |= a_in != 0
        coupled[:-1] |= b != 0
        coupled[1:] |= b != 0
        width = np.where(coupled.any(axis=1), m - np.argmax(coupled[:, ::-1], axis=1), 0)
        # Contiguous float64 rows: the digest reads their bytes in place.
        diag, off_in, off_between = (np.ascontiguousarray(a, dtype=float) for a in (diag, off_in, off_between))
        G = []
        prev, w_prev = None, 0
        # Row j's inverse is a function of the rows up to j as far as they are coupled: their
        # diagonals (the scale), in-row couplings, couplings to the row above and widths.  A
        # running digest of exactly those numbers names it; where the prefix is one already
        # eliminated (another configuration of the same probe), its inverse is taken as it is.
        h = hashlib.blake2b(digest_size=20)
        update = h.update
        n_shared = n if shared_rows is None else max(0, min(int(shared_rows), n))
        for j in range(n):
            w = int(width[j])
            c = min(w, w_prev) if j else 0
            if j < n_shared:
                update(w.to_bytes(4, "little"))
                update(diag[j, :w])
                update(off_in[j, : max(w - 1, 0)])
                if c:
                    update(diag[j - 1, :c])
                    update(off_between[j - 1, :c])
                key = h.digest()
                hit = _cached_row(key)
                if hit is not None:
                    prev, w_prev = hit, w
                    G.append(prev)
                    continue
            # The scaled row: unit diagonal, its in-row couplings either side of it.
            S = np.zeros((w, w))
            flat = S.reshape(-1)
            flat[:: w + 1] = 1.0
            if w > 1:
                a = a_in[j, : w - 1]
                flat[1:: w + 1] = a
                flat[w:: w + 1] = a
            if prev is not None and c:
                # Only the leading min(w, w_prev) unknowns of the two rows can be coupled:
                # S -= diag(b) G_prev diag(b), the products in the order written.
                bj = b[j - 1, :c]
                t = bj[:, None] * prev[:c, :c]
                t *= bj
                S[:c, :c] -= t
            if w:
                prev = _inverse(S)
                # Symmetrise: S_j is symmetric, its computed inverse only to round-off.
                prev = prev + prev.T
                prev *= 0.5
            else:
                prev = S
            if j < n_shared:
                _keep_row(key, prev)
            w_prev = w
            G.append(prev)
        self.n, self.m = n, m
        self._plan(G, width, b)

    def _plan(self, G: list[np.ndarray], width: np.ndarray, b: np.ndarray) -> None:
        """Per-row operands of the two sweeps, laid out for four NumPy calls per row.

        The elimination written out is, per block row j with coupled width w_j (``c`` the
        unknowns coupled to the next row, ``b = b_{j+1}[:c]``):

        * forward, ``z_j = G_j (f_j - b_j z_{j-1})``;
        * back, ``x_j = z_j - G_j[:, :c] (b x_{j+1}[:c])``.

        Each row's unknowns are carried scaled by ``beta_j`` (``b`` on the coupled ones, 1 on
        the rest): the forward sweep keeps ``u_j = beta_j z_j``, whose leading ``c`` entries
        are the very coupling the next row subtracts, and the back sweep ``v_j = beta_j x_j``;
        the solution is ``v / beta`` at the end, for all rows at once.  With ``F_j = diag(beta_j)
        G_j`` and ``M_j = diag(beta_j) G_j[:, :c] diag(b / beta_{j+1}[:c])`` a row is a
        subtraction and a mat-vec each way, where the unscaled sweeps take a multiplication
        more (a row's cost is its NumPy calls as much as its flops).  A coupling that is
        exactly zero cannot carry a scale: its ``beta`` is 1 and the forward subtraction of
        that row is masked (a multiplication more; no grid built here has one).  The work
        vector holds, per row, a slot ``F_j`` (the right-hand side, then ``v_j``) followed
        by ``U_j``.
        """
        n, m = self.n, self.m
        w = [int(x) for x in width]
        f_at, pos = [], 0
        for j in range(n):
            f_at.append(pos)
            pos += 2 * w[j]
        self._size = pos
        # beta_j on the leading c_j = min(w_j, w_{j+1}) unknowns (1 where the coupling is zero,
        # and past them), for every row at once: a row of the (n, m) table per block row.
        wa = np.asarray(w, dtype=np.intp)
        cols = np.arange(m)
        in_c = cols < np.minimum(wa[:-1], wa[1:])[:, None]       # (n - 1, m)
        zero = b == 0
        table = np.ones((n, m))
        if n > 1:
            table[:-1] = np.where(in_c & ~zero, b, 1.0)
        beta = [table[j, :w[j]] for j in range(n)]
        mask = [None] * n
        for j in np.flatnonzero((in_c & zero).any(axis=1)):
            mask[j + 1] = (~zero[j, :min(w[j], w[j + 1])]).astype(float)
        fwd, back = [], []
        F = [beta[j][:, None] * G[j] if w[j] else None for j in range(n)]
        for j in range(n):
            if not w[j]:
                continue
            wp = w[j - 1] if j else 0
            c = min(w[j], wp)
            fwd.append((F[j], f_at[j], f_at[j] + w[j], c, f_at[j - 1] + wp, mask[j]))
        for j in range(n - 1, -1, -1):
            if not w[j]:
                continue
            wn = w[j + 1] if j < n - 1 else 0
            c = min(w[j], wn)
            if c:
                scale = b[j, :c] / beta[j + 1][:c]
                back.append((F[j][:, :c] * scale, f_at[j + 1], f_at[j] + w[j], f_at[j]))
            else:
                back.append((None, 0, f_at[j] + w[j], f_at[j]))
        self._fwd, self._back = fwd, back
        # Where each row's coupled unknowns sit in the (n, m) field and in the work vector.
        # (Row-major: row j's leading w_j unknowns in order, as the rows' slots hold them.)
        field_idx = np.flatnonzero(cols < wa[:, None]).astype(np.intp)
        self._field_idx = field_idx
        self._work_idx = (np.repeat(np.asarray(f_at, dtype=np.intp) - np.arange(n, dtype=np.intp) * m, wa)
                          + field_idx).astype(np.intp)
        self._beta = np.concatenate(beta) if n else np.zeros(0)
        # Every row as wide as the field (a probe on an object): the rows' slots are a strided
        # view of the work vector, a plain copy where the general layout gathers and scatters.
        self._full = n > 0 and all(x == self.m for x in w)
        self.nbytes = sum(e[0].nbytes for e in fwd) + sum(e[0].nbytes for e in back if e[0] is not None)
        # Work vectors and their per-row views, one set per thread (factors are shared between
        # solvers, and worlds may step in different threads).
        self._local = threading.local()

    def _views(self) -> tuple[np.ndarray, list, list, bool]:
        loc = self._local
        views = getattr(loc, "views", None)
        if views is None:
            buf = np.empty(self._size)
            # Bound methods: ``ndarray.dot`` skips ``np.dot``'s dispatch, a third of a small
            # mat-vec's cost here (the same BLAS call, the same bits).  Each row is a fixed pair of
            # calls, without branches: a row not coupled to the one above subtracts empty slices
            # (nothing), one not coupled to the one below subtracts the zeros an empty mat-vec
            # writes (``x - 0.0`` is ``x``, bit for bit, -0.0 and NaN included).
            masked = any(e[5] is not None for e in self._fwd)
            fwd = []
            for F, f, u, c, up, m in self._fwd:
                w = u - f
                if masked:
                    coupled = (buf[f:f + c], buf[up:up + c]) if c else (None, None)
                    fwd.append((F.dot, buf[f:u], buf[u:u + w]) + coupled
                               + (m, np.empty(c) if m is not None else None))
                else:
                    fwd.append((F.dot, buf[f:u], buf[u:u + w], buf[f:f + c], buf[up:up + c]))
            back = []
            for M, vn, u, f in self._back:
                w = u - f
                if M is None:
                    back.append((np.zeros((w, 0)).dot, np.zeros(0), buf[u:u + w], buf[f:f + w], np.empty(w)))
                else:
                    back.append((M.dot, buf[vn:vn + M.shape[1]], buf[u:u + w], buf[f:f + w], np.empty(w)))
            views = loc.views = (buf, fwd, back, masked)
        return views

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve ``A x = rhs`` for ``rhs`` of shape (n, m); returns a new (n, m) array."""
        buf, fwd, back, masked = self._views()
        if self._full:
            slots = buf.reshape(self.n, 2 * self.m)[:, :self.m]
            np.multiply(rhs, self.scale, out=slots)
        else:
            f = (rhs * self.scale).reshape(-1)
            buf[self._work_idx] = f[self._field_idx]
        subtract = np.subtract
        if masked:
            multiply = np.multiply
            for F_dot, fj, uj, fj_c, u_prev, m, tmp in fwd:
                if fj_c is not None:
                    if m is None:
                        subtract(fj_c, u_prev, fj_c)
                    else:
                        multiply(m, u_prev, tmp)
                        subtract(fj_c, tmp, fj_c)
                F_dot(fj, uj)
        else:
            # The hot loop (every grid built here): two calls a row, positional ``out`` (a
            # keyword costs a ufunc call a dict parse).
            for F_dot, fj, uj, fj_c, u_prev in fwd:
                subtract(fj_c, u_prev, fj_c)
                F_dot(fj, uj)
        for M_dot, vn, u, out, tmp in back:
            M_dot(vn, tmp)
            subtract(u, tmp, out)
        if self._full:
            return slots / self._beta.reshape(self.n, self.m) * self.scale
        # Uncoupled unknowns keep f (scaled twice: rhs / diag).
        f[self._field_idx] = buf[self._work_idx] / self._beta
        return f.reshape(self.n, self.m) * self.scale
