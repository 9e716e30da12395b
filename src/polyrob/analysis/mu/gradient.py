"""The D-G upper bound of μ by quasi-Newton descent on the scalings.

The mixed-μ upper bound (Fan, Tits & Doyle) holds with any admissible
scalings: if ``P = D²`` commutes with Δ, ``G`` is Hermitian and nonzero only
on the real blocks, and

.. math:: M^* P M + j(G M - M^* G) - \\beta^2 P \\prec 0,

then ``μ(M) < β``.  Writing ``P = T^* T`` with ``T`` block diagonal and
``G = T^* \\tilde G T``, the least such ``β`` is
``sqrt(λ_max(\\tilde M^* \\tilde M + j(\\tilde G \\tilde M - \\tilde M^* \\tilde G)))``
with ``\\tilde M = T M T^{-1}``: a function of the scalings that costs one
Hermitian eigen-decomposition.  :class:`GradientUpper` minimises a smoothed
version of it with L-BFGS (analytic gradient) and then re-certifies the
scalings it found with :func:`~polyrob.analysis.mu.upper.certified_beta`, so
the bound is exact whatever the optimiser reached: it can only be
conservative, never wrong.

Why by hand: SLICOT AB13MD, the only maintained μ code python reaches, takes
no repeated scalar blocks, and the D-G LMI (cvxpy) of an 89-channel
structure takes minutes per frequency.  MATLAB's ``mussv`` offers the same
two routes: a gradient method on the scalings (its ``'G'`` option; Young,
Newlin & Doyle, 1995) and the LMI for the greatest accuracy (``'a'``).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy import optimize

from polyrob.analysis.mu.blocks import BlockStructure, perron_upper
from polyrob.analysis.mu.upper import certified_beta
from polyrob.errors import ArgumentError

__all__ = ["GradientUpper"]

#: Temperatures of the smoothed largest eigenvalue, relative to the current bound.
_TEMPERATURES = (1e-2, 1e-3)


class GradientUpper:
    """Mixed-μ upper bound with full scalings on repeated blocks, by descent.

    Parameters
    ----------
    st : BlockStructure
        Any structure (repeated real or complex scalars, full blocks).
    maxiter : int
        L-BFGS iterations per temperature.
    temperatures : sequence of float
        Smoothing of the largest eigenvalue, relative to the current bound,
        one L-BFGS run each (a D-K iteration's D-step needs less than a
        certificate: fewer and coarser steps there).
    hermitian : sequence of int
        Indices of square full blocks whose members are Hermitian (a real
        symmetric matrix error, e.g. an inertia's): they take a scalar
        ``G = g I`` too, which is admissible because ``j w^* (Delta^* G - G
        Delta) w = 0`` for ``Delta = Delta^*``.  The bound is then one for
        that smaller set, not for a complex block (MATLAB's ``blk`` has no
        such block; ``mussv`` below does not pass it).

    Examples
    --------
    A repeated real scalar: μ of ``M`` against ``δ I_2`` is the largest
    absolute real eigenvalue of ``M`` when ``M`` has only real eigenvalues.

    >>> import numpy as np
    >>> from polyrob.analysis.mu.blocks import as_block_structure
    >>> from polyrob.analysis.mu.gradient import GradientUpper
    >>> M = np.array([[0.5, 2.0], [0.0, -1.5]])
    >>> beta, D, G, x = GradientUpper(as_block_structure([[-2, 0]]))(M.astype(complex))
    >>> print(f"{beta:.3f}")
    1.500

    ``M = 2j I`` is made singular by no Hermitian ``I - M Delta`` (its
    eigenvalues ``1 - 2j lambda``), while a complex block of norm 1/2 does:

    >>> full = as_block_structure([[2, 2]])
    >>> M = 2j * np.eye(2)
    >>> print(f"{GradientUpper(full)(M)[0]:.3f} {GradientUpper(full, hermitian=[0])(M)[0] < 1e-3}")
    2.000 True
    """

    def __init__(self, st: BlockStructure, maxiter: int = 150, temperatures=_TEMPERATURES, hermitian=()):
        self.st, self.maxiter, self.temperatures = st, maxiter, tuple(temperatures)
        self.hermitian = frozenset(int(i) for i in hermitian)
        for i in self.hermitian:
            b = st.blocks[i]
            if b.kind == "real" or b.repeated or b.rows != b.cols:
                raise ArgumentError(f"hermitian: block {i} is not a square full block ({b.matlab})")
        #: eigenpairs computed per step (doubled while they all weigh in the smoothed maximum)
        self.top = 16
        #: evaluations of the smoothed bound and its gradient so far (the descent's unit of work)
        self.evaluations = 0
        self._layout = []
        k = 0
        for i, (b, sl) in enumerate(zip(st.blocks, st.padded_slices)):
            n = sl.stop - sl.start
            full_t = b.repeated  # full T (D) on repeated scalars, t*I elsewhere
            nt = 2 * n * n if full_t else 1
            ng = (n * n if full_t else 1) if b.kind == "real" or i in self.hermitian else 0
            self._layout.append((sl, n, full_t, slice(k, k + nt), slice(k + nt, k + nt + ng)))
            k += nt + ng
        self.size = k
        self._iu = {}
        self._index()
        # scalar scalings stay within e^+-30 of each other (beyond, products overflow)
        self._bounds = [(None, None)] * k
        for _, _, full_t, st_t, _ in self._layout:
            if not full_t:
                self._bounds[st_t.start] = (-30.0, 30.0)

    # ------------------------------------------------------------ parameters
    def _triu(self, n):
        if n not in self._iu:
            self._iu[n] = np.triu_indices(n, 1)
        return self._iu[n]

    def initial(self, Ms: np.ndarray) -> np.ndarray:
        """Start at the Perron scaling ``D = diag(d_i I)``, ``G = 0``."""
        _, Dp = perron_upper(Ms, self.st)
        d = np.clip(np.diag(Dp).real, np.exp(-30.0), np.exp(30.0))
        x = np.zeros(self.size)
        for sl, n, full_t, st_t, _ in self._layout:
            if full_t:
                T = np.eye(n) * d[sl.start]
                x[st_t] = np.concatenate([T.ravel(), np.zeros(n * n)])
            else:
                x[st_t] = np.log(d[sl.start])
        return x

    def _index(self):
        """Gather/scatter indices of the block-diagonal ``T``, ``T^-1`` and ``G~`` in the parameter vector.

        The scalings are assembled and the gradient read with a few fancy-index
        operations instead of a Python loop over the blocks (a 90-channel
        structure has 20-odd blocks; the loop was most of an objective's time).
        """
        nn = self.st.padded_size
        t_flat, t_flat_tr, t_re, t_im = [], [], [], []  # full T: entries, their transposes, parameters
        s_diag, s_block, s_param = [], [], []  # t*I blocks: diagonal positions, block number, parameter
        g_diag, g_diag_param, g_up, g_lo, g_up_re, g_up_im = [], [], [], [], [], []
        gs_diag, gs_block, gs_param = [], [], []  # g*I blocks
        by_size = {}
        for sl, n, full_t, st_t, st_g in self._layout:
            s0 = sl.start
            rows, cols = np.divmod(np.arange(n * n), n)
            if full_t:
                t_flat.append((s0 + rows) * nn + s0 + cols)
                t_flat_tr.append((s0 + cols) * nn + s0 + rows)
                t_re.append(st_t.start + np.arange(n * n))
                t_im.append(st_t.start + n * n + np.arange(n * n))
                by_size.setdefault(n, []).append(s0)
            else:
                s_diag.append(s0 + np.arange(n))
                s_block.append(np.full(n, len(s_param)))
                s_param.append(st_t.start)
            if st_g.stop > st_g.start:
                if full_t:
                    iu = self._triu(n)
                    m = len(iu[0])
                    g_diag.append((s0 + np.arange(n)) * (nn + 1))
                    g_diag_param.append(st_g.start + np.arange(n))
                    g_up.append((s0 + iu[0]) * nn + s0 + iu[1])
                    g_lo.append((s0 + iu[1]) * nn + s0 + iu[0])
                    g_up_re.append(st_g.start + n + np.arange(m))
                    g_up_im.append(st_g.start + n + m + np.arange(m))
                else:
                    gs_diag.append(s0 + np.arange(n))
                    gs_block.append(np.full(n, len(gs_param)))
                    gs_param.append(st_g.start)

        def cat(parts):
            return np.concatenate(parts).astype(np.intp) if parts else np.zeros(0, np.intp)

        self._t_flat, self._t_flat_tr, self._t_re, self._t_im = map(cat, (t_flat, t_flat_tr, t_re, t_im))
        self._s_diag, self._s_block = cat(s_diag), cat(s_block)
        self._s_param = np.asarray(s_param, np.intp)
        self._g_diag, self._g_diag_param = cat(g_diag), cat(g_diag_param)
        self._g_up, self._g_lo, self._g_up_re, self._g_up_im = map(cat, (g_up, g_lo, g_up_re, g_up_im))
        self._gs_diag, self._gs_block = cat(gs_diag), cat(gs_block)
        self._gs_param = np.asarray(gs_param, np.intp)
        # full T blocks of one size are inverted together: (rows, cols) of each stacked block
        self._t_sizes = []
        for n, starts in by_size.items():
            starts = np.asarray(starts)
            r = starts[:, None, None] + np.arange(n)[None, :, None]
            c = starts[:, None, None] + np.arange(n)[None, None, :]
            self._t_sizes.append((r * nn + c).reshape(len(starts), n, n))

    def _unpack(self, x):
        nn = self.st.padded_size
        T, Ti, Gt = np.zeros((nn, nn), complex), np.zeros((nn, nn), complex), np.zeros((nn, nn), complex)
        T.flat[self._t_flat] = x[self._t_re] + 1j * x[self._t_im]
        for flat in self._t_sizes:
            Ti.flat[flat] = np.linalg.inv(T.flat[flat])
        t = np.exp(np.clip(x[self._s_param], -300, 300))
        T.flat[self._s_diag * (nn + 1)] = t[self._s_block]
        Ti.flat[self._s_diag * (nn + 1)] = 1.0 / t[self._s_block]
        Gt.flat[self._g_diag] = x[self._g_diag_param]
        up = x[self._g_up_re] + 1j * x[self._g_up_im]
        Gt.flat[self._g_up] = up
        Gt.flat[self._g_lo] = up.conj()
        Gt.flat[self._gs_diag * (nn + 1)] = x[self._gs_param][self._gs_block]
        return T, Ti, Gt

    def _scaled(self, Ms, T, Ti):
        """``T Ms T^-1`` (``T`` is block diagonal; one product each side beats a loop over the blocks)."""
        return T @ Ms @ Ti

    def _hermitian(self, Ms, x):
        T, Ti, Gt = self._unpack(x)
        Mt = self._scaled(Ms, T, Ti)
        GM = Gt @ Mt
        H = Mt.conj().T @ Mt + 1j * (GM - GM.conj().T)
        return (H + H.conj().T) / 2, Mt, T, Ti, Gt

    def _top(self, H, temp):
        """Eigenpairs of ``H`` that carry weight in the smoothed maximum (the top few)."""
        n = H.shape[0]
        k = min(n, self.top)
        while True:
            if k >= n:
                return np.linalg.eigh(H)
            lam, V = sla.eigh(H, subset_by_index=[n - k, n - 1], driver="evx")
            if lam[-1] - lam[0] > 40 * temp:  # the rest weighs below exp(-40)
                return lam, V
            k *= 2

    def _objective(self, x, Ms, temp):
        # A block that barely couples to the rest drives its scaling to infinity (the bound's
        # infimum is not attained): where the numbers overflow, report +inf so the line search
        # steps back, instead of warnings and NaN.
        self.evaluations += 1
        with np.errstate(all="ignore"):
            try:
                f, g = self._objective_raw(x, Ms, temp)
            except (np.linalg.LinAlgError, ValueError):
                return np.inf, np.zeros_like(x)
        if not (np.isfinite(f) and np.all(np.isfinite(g))):
            return np.inf, np.zeros_like(x)
        return f, g

    def _objective_raw(self, x, Ms, temp):
        H, Mt, T, Ti, Gt = self._hermitian(Ms, x)
        lam, V = self._top(H, temp)
        top = lam[-1]
        w = np.exp((lam - top) / temp)
        f = top + temp * np.log(w.sum())
        p = w / w.sum()
        # d f = tr(W dH), W = V diag(p) V^H (low rank):
        #   = 2 Re tr(Phi dMt) + 2 Re tr(Y dGt),  Phi = W (Mt^H + j Gt),  Y = j Mt W,
        #   dMt = E Mt - Mt E with E = dT T^-1, so the T part is 2 Re tr(T^-1 (Mt Phi - Phi Mt) dT);
        # only the diagonal blocks are needed, each from the low-rank factors.
        # every block's diagonal block at once: X = (Mt V) diag(p) Z - V diag(p) Z Mt, A = T^-1 X, Y = j Mt W
        Vh = V.conj().T
        Z = Vh @ Mt.conj().T + 1j * (Vh @ Gt)  # Z = V^H (Mt^H + j Gt), Phi = V diag(p) Z
        MVp = (Mt @ V) * p
        A = Ti @ (MVp @ Z - (V * p) @ (Z @ Mt))
        g = np.zeros_like(x)
        a = A.ravel()[self._t_flat_tr]  # Ab.T of each full block, row by row
        g[self._t_re] = 2 * a.real
        g[self._t_im] = -2 * a.imag
        nn = Mt.shape[0]
        if len(self._s_param):
            tr = np.bincount(self._s_block, weights=A.diagonal()[self._s_diag].real, minlength=len(self._s_param))
            g[self._s_param] = 2 * tr * np.exp(np.clip(x[self._s_param], -300, 300))
        if len(self._g_diag_param) or len(self._gs_param):
            y = (1j * (MVp @ Vh)).ravel()
            g[self._g_diag_param] = 2 * y[self._g_diag].real
            up, lo = y[self._g_up], y[self._g_lo]
            g[self._g_up_re] = 2 * (lo + up).real
            g[self._g_up_im] = 2 * (up - lo).imag
            if len(self._gs_param):
                yd = y[self._gs_diag * (nn + 1)].real
                g[self._gs_param] = 2 * np.bincount(self._gs_block, weights=yd, minlength=len(self._gs_param))
        return f, g

    def scalings(self, x) -> tuple[np.ndarray, np.ndarray]:
        """``(P, G)`` of the LMI for the parameter vector ``x``."""
        T, _, Gt = self._unpack(x)
        return T.conj().T @ T, T.conj().T @ Gt @ T

    def __call__(self, Ms: np.ndarray, x0: np.ndarray | None = None):
        """Upper bound of ``μ(Ms)`` on the padded square problem.

        Parameters
        ----------
        Ms : (n, n) complex ndarray
            Padded square matrix (:meth:`BlockStructure.pad`).
        x0 : ndarray, optional
            Parameters to start from (e.g. the previous frequency's); the
            Perron scaling otherwise.

        Returns
        -------
        beta : float
            The certified bound (re-derived from the scalings).
        D, G : ndarray
            Padded scalings (``D = P^{1/2}``) that certify ``beta``.
        x : ndarray
            The parameters reached, to warm-start the next call.
        """
        n = Ms.shape[0]
        x_init = self.initial(Ms)
        starts = [x_init] if x0 is None or x0.shape != x_init.shape else [x0, x_init]
        best_x, best_f = None, np.inf
        for xs in starts:
            f0 = self._objective(xs, Ms, 1e-12 + 1e-2 * max(np.linalg.norm(Ms, 2) ** 2, 1e-300))[0]
            if f0 < best_f:
                best_x, best_f = xs, f0
        x = best_x
        for rel in self.temperatures:
            lam_top = max(np.linalg.eigvalsh(self._hermitian(Ms, x)[0])[-1], 1e-300)
            res = optimize.minimize(
                self._objective,
                x,
                args=(Ms, rel * lam_top),
                jac=True,
                method="L-BFGS-B",
                bounds=self._bounds,
                options={"maxiter": self.maxiter, "ftol": 1e-12, "gtol": 1e-10},
            )
            if np.all(np.isfinite(res.x)):
                x = res.x
        P, G = self.scalings(x)
        beta, P = certified_beta(Ms, P, G)
        best = (beta, P, G)
        # the Perron scaling alone (G = 0) is a bound too: never return worse
        bp, Dp = perron_upper(Ms, self.st)
        if bp < best[0]:
            best = (bp, (Dp @ Dp).astype(complex), np.zeros((n, n), complex))
        beta, P, G = best
        D = sla.sqrtm(P)
        return float(beta), (D + D.conj().T) / 2, (G + G.conj().T) / 2, x
