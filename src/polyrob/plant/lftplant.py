"""The uncertain plant object: an LFT ``G(Δ) = Fu(M, Δ)`` shared by every uncertainty model.

:class:`UncertainPlant` is what the rest of polyrob (generalized plant,
μ-analysis, synthesis, Monte Carlo) consumes, whatever model of the PLDI
built it (:mod:`polyrob.plant.uncertainty` chooses: ``box``, ``axes``,
``lft``).  It is MATLAB's ``uss``::

    ẋ = A_mid x + B_d d + B_mid u          d = Δ v
    v = C_v x  + D_vd d + D_vu u           Δ = diag(blocks)
    y = C x                                C = [I_m 0]  (y = q)

``Δ`` holds normalised real parameters ``δ_i ∈ [-1, 1]`` (each repeated on
``r_i`` channels, MATLAB block ``[-r_i, 0]``) and, for the ``axes`` model, a
full complex block with ``‖Δ_full‖ <= 1`` that carries the residual.  The
full-block channels come first in ``Δ``, then the real ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import control
import numpy as np

from polyrob.errors import ArgumentError

__all__ = ["UncertainPlant", "upper_lft", "upper_lft_matrices", "MAX_CORNERS", "weakest_enclosure"]

#: Default cap on the number of corners :meth:`UncertainPlant.corners` enumerates.
MAX_CORNERS = 1024


def weakest_enclosure(*levels) -> str:
    """``"certified"`` if every level is ``"certified"``, else ``"sampled"`` (a missing level is sampled).

    >>> weakest_enclosure("certified", "sampled"), weakest_enclosure("certified"), weakest_enclosure(None)
    ('sampled', 'certified', 'sampled')
    """
    return "certified" if levels and all(level == "certified" for level in levels) else "sampled"


def upper_lft_matrices(A, B, C, D, Delta):
    """Matrices of ``Fu(M, Δ)`` for a constant ``Δ`` closing ``d = Δ v`` on the first inputs and outputs.

    With ``Q = (I - Δ D11)^{-1} Δ``: ``(A + B1 Q C1, B2 + B1 Q D12, C2 + D21 Q C1,
    D22 + D21 Q D12)``.  python-control's ``StateSpace.lft`` is the lower LFT
    with a system; the upper one with a constant is these three products,
    written once here.  Raises :class:`~polyrob.errors.PolyrobError` when
    ``I - Δ D11`` is singular.
    """
    nd, nv = Delta.shape
    B1, B2 = B[:, :nd], B[:, nd:]
    C1, C2 = C[:nv], C[nv:]
    D11, D12, D21, D22 = D[:nv, :nd], D[:nv, nd:], D[nv:, :nd], D[nv:, nd:]
    if nd == 0:
        return A.copy(), B2.copy(), C2.copy(), D22.copy()
    lhs = np.eye(nd) - Delta @ D11
    if np.linalg.cond(lhs) > 1e12:
        raise ArgumentError("the upper LFT is ill posed: I - Δ D_vd is singular")
    Q = np.linalg.solve(lhs, Delta)
    return A + B1 @ Q @ C1, B2 + B1 @ Q @ D12, C2 + D21 @ Q @ C1, D22 + D21 @ Q @ D12


def upper_lft(M: control.StateSpace, Delta) -> control.StateSpace:
    """Upper LFT ``Fu(M, Δ)`` with a constant (real or complex) ``Δ`` (:func:`upper_lft_matrices`).

    The first ``Δ.shape[0]`` inputs of ``M`` are ``d`` and its first
    ``Δ.shape[1]`` outputs are ``v``; ``d = Δ v`` closes them (MATLAB's
    ``lft(Delta, M)``).

    Raises
    ------
    PolyrobError
        ``Δ`` too large for ``M``, or the loop is ill posed (``I - Δ D11`` singular).

    Examples
    --------
    >>> import control, numpy as np
    >>> from polyrob.plant.uncertainty import upper_lft
    >>> M = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], np.zeros((2, 2)))
    >>> upper_lft(M, [[2.0]]).A    # x' = -x + d, d = 2 x
    array([[1.]])
    """
    Delta = np.atleast_2d(np.asarray(Delta))
    nd, nv = Delta.shape
    if nd > M.ninputs or nv > M.noutputs:
        raise ArgumentError(f"Δ is {nd}x{nv} but M has only {M.ninputs} inputs and {M.noutputs} outputs")
    return control.ss(
        *upper_lft_matrices(*(np.asarray(X) for X in (M.A, M.B, M.C, M.D)), Delta),
        inputs=M.input_labels[nd:],
        outputs=M.output_labels[nv:],
        states=M.state_labels,
        dt=M.dt,
    )


@dataclass(frozen=True, eq=False)
class UncertainPlant:
    """A PLDI as an LFT in normalised parameters (MATLAB's ``uss``).

    Build it with :func:`polyrob.plant.uncertainty.uncertain_plant`.
    *Parameters* are the independent normalised reals ``δ``; *channels* are
    the rows of ``Δ`` (a parameter repeated ``r`` times has ``r`` channels;
    a full block of size ``k`` has ``k`` channels and parameter index -1).

    Attributes
    ----------
    robot_name : str
    model : {"box", "axes", "lft", "lft-torque", "inertia"}
        The uncertainty model (:func:`~polyrob.plant.uncertainty.uncertain_plant`).
    nominal_kind : {"pldi", "midpoint"}
    A_nom, B_nom, C : ndarray
        The nominal ``G_n = (A_nom, B_nom, C, 0)``; ``C = [I_m 0]``.
    A_mid, B_mid : ndarray
        The LFT centre (``Δ = 0``).
    B_d, C_v, D_vu, D_vd : ndarray
        Uncertainty channels: ``ẋ += B_d d``, ``v = C_v x + D_vd d + D_vu u``.
    parameter_names : tuple of str
    parameter_lower, parameter_upper : ndarray (n_params,)
        Physical range of each parameter (an entry's interval for ``box``).
    channel_names : tuple of str
    channel_parameter : ndarray (n_delta,) of int
        Parameter of each channel (-1 for a full-block channel).
    channel_index, channel_lower, channel_upper : ndarray or None
        ``box`` only: matrix (0 = A, 1 = B), row, column and interval of
        each channel's entry.
    nominal_delta : ndarray (n_params,)
        ``δ`` at which the LFT (with the full blocks at 0) equals the nominal.
    offset : ndarray (n_params,)
        Centre minus nominal, in the parameters' physical units.
    block_structure : ndarray (n_blocks, 2) of int
        MATLAB ``blk`` rows in ``Δ`` order.
    merged : tuple of tuple of str
    coverage : float
        Fraction of ``coverage_points`` fresh domain samples whose Jacobians
        the model contains (NaN when not checked).
    volume_ratio : float
        Size of the model's set over the polytope's (see docs/uncertainty.md); NaN if unknown.
    info : dict
        Model-specific figures (retained directions, residual gain, ...).
    """

    robot_name: str
    nominal_kind: str
    A_nom: np.ndarray
    B_nom: np.ndarray
    C: np.ndarray
    A_mid: np.ndarray
    B_mid: np.ndarray
    B_d: np.ndarray
    C_v: np.ndarray
    D_vu: np.ndarray
    parameter_names: tuple[str, ...]
    parameter_lower: np.ndarray
    parameter_upper: np.ndarray
    channel_names: tuple[str, ...]
    channel_parameter: np.ndarray
    channel_index: np.ndarray | None
    channel_lower: np.ndarray | None
    channel_upper: np.ndarray | None
    nominal_delta: np.ndarray
    offset: np.ndarray
    block_structure: np.ndarray
    merged: tuple[tuple[str, ...], ...] = ()
    info: dict = field(default_factory=dict)
    model: str = "box"
    D_vd: np.ndarray | None = None
    coverage: float = float("nan")
    coverage_points: int = 0
    volume_ratio: float = float("nan")

    def __post_init__(self):
        if self.D_vd is None:
            object.__setattr__(self, "D_vd", np.zeros((self.n_delta, self.n_delta)))

    # ------------------------------------------------------------------ sizes
    @property
    def m(self) -> int:
        """Number of joints (inputs ``u`` and outputs ``y = q``)."""
        return self.B_nom.shape[1]

    @property
    def n_x(self) -> int:
        return self.A_nom.shape[0]

    @property
    def n_delta(self) -> int:
        """Number of uncertainty channels (rows of ``Δ``)."""
        return len(self.channel_names)

    @property
    def n_params(self) -> int:
        """Number of independent real parameters."""
        return len(self.parameter_names)

    @property
    def full_blocks(self) -> list[int]:
        """Sizes of the full complex blocks (the residual), in ``Δ`` order."""
        return [int(r) for r, c in self.block_structure if c > 0]

    @property
    def ranges(self) -> dict[str, tuple[float, float]]:
        """``{parameter: (lower, upper)}``, MATLAB's ``ureal`` ``Range``."""
        return {
            n: (float(lo), float(hi))
            for n, lo, hi in zip(self.parameter_names, self.parameter_lower, self.parameter_upper)
        }

    @property
    def nominal_inside(self) -> bool:
        """Whether the nominal lies in the model's parameter box (``|δ_n| <= 1``)."""
        return bool(np.all(np.abs(self.nominal_delta) <= 1.0 + 1e-12))

    def signal_labels(self):
        """Labels ``(u, y, x, d, v)`` of the plant's signals."""
        m = self.m
        u = [f"u[{i}]" for i in range(m)]
        y = [f"y[{i}]" for i in range(m)]
        x = [f"q[{i}]" for i in range(m)] + [f"qdot[{i}]" for i in range(m)]
        d = [f"d_{n}" for n in self.channel_names]
        v = [f"v_{n}" for n in self.channel_names]
        return u, y, x, d, v

    _labels = signal_labels

    # ------------------------------------------------------------------ systems
    def _ss(self, A, B, name):
        u, y, x, _, _ = self.signal_labels()
        return control.ss(A, B, self.C, np.zeros((self.m, self.m)), inputs=u, outputs=y, states=x, name=name, dt=0)

    def nominal_system(self) -> control.StateSpace:
        """The nominal plant ``G_n = (A_nom, B_nom, [I 0], 0)`` (eq. 7)."""
        return self._ss(self.A_nom, self.B_nom, "G_n")

    def midpoint_system(self) -> control.StateSpace:
        """The LFT centre ``(A_mid, B_mid, C, 0)`` (``Δ = 0``)."""
        return self._ss(self.A_mid, self.B_mid, "G_mid")

    def lft_system(self) -> control.StateSpace:
        """``M`` with ``G(Δ) = Fu(M, Δ)``: inputs ``[d, u]``, outputs ``[v, y]``."""
        u, y, x, d, v = self.signal_labels()
        nd, m = self.n_delta, self.m
        B = np.hstack([self.B_d, self.B_mid])
        C = np.vstack([self.C_v, self.C])
        D = np.zeros((nd + m, nd + m))
        D[:nd, :nd] = self.D_vd
        D[:nd, nd:] = self.D_vu
        return control.ss(self.A_mid, B, C, D, inputs=d + u, outputs=v + y, states=x, name="M", dt=0)

    # ------------------------------------------------------------------ δ handling
    def check_delta(self, delta, strict: bool = True) -> np.ndarray:
        """``δ`` as a float array of one value per parameter (``|δ| <= 1`` when ``strict``)."""
        delta = np.asarray(delta, dtype=float)
        if delta.shape != (self.n_params,):
            raise ArgumentError(
                f"δ must have one value per parameter ({self.n_params}: {', '.join(self.parameter_names)}), "
                f"got shape {delta.shape}"
            )
        if not np.all(np.isfinite(delta)):
            raise ArgumentError("δ must be finite")
        if strict and np.any(np.abs(delta) > 1.0 + 1e-12):
            raise ArgumentError(
                f"δ must lie in [-1, 1] (max |δ| = {np.abs(delta).max():.6g}); pass strict=False to extrapolate"
            )
        return delta

    _check_delta = check_delta

    def delta_matrix(self, delta, residual=None) -> np.ndarray:
        """``Δ`` (``n_delta x n_delta``): the full blocks (``residual``, a list of matrices, 0 if
        omitted), then ``diag(δ)`` over the real channels (a repeated parameter repeats)."""
        delta = self.check_delta(delta, strict=False)
        nd = self.n_delta
        complex_ = residual is not None and any(np.iscomplexobj(R) for R in residual)  # blocks of several sizes
        D = np.zeros((nd, nd), dtype=complex if complex_ else float)
        real = self.channel_parameter >= 0
        D[np.flatnonzero(real), np.flatnonzero(real)] = delta[self.channel_parameter[real]]
        if residual is not None:
            start = 0
            for size, R in zip(self.full_blocks, residual):
                R = np.asarray(R)
                if R.shape != (size, size):
                    raise ArgumentError(f"a residual block must be {size}x{size}, got {R.shape}")
                D[start : start + size, start : start + size] = R
                start += size
        return D

    def matrices_at(self, delta, *, residual=None, strict: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """``(A(δ), B(δ))``, the full blocks at ``residual`` (0 by default).

        For the ``box`` model each entry is ``((1 - δ)/2) lo + ((1 + δ)/2) hi``,
        which hits ``lo``/``hi`` exactly at ``δ = ∓1`` and (clipped) never leaves
        ``[lo, hi]`` for ``|δ| <= 1``; other models evaluate the upper LFT.
        """
        delta = self.check_delta(delta, strict)
        if self.channel_index is not None and residual is None:
            A, B = self.A_mid.copy(), self.B_mid.copy()
            dch = delta[self.channel_parameter]
            lo, hi = self.channel_lower, self.channel_upper
            vals = 0.5 * (1.0 - dch) * lo + 0.5 * (1.0 + dch) * hi
            inside = np.abs(dch) <= 1.0
            vals = np.where(inside, np.clip(vals, lo, hi), vals)
            for (mat, r, c), val in zip(self.channel_index, vals):
                (A if mat == 0 else B)[r, c] = val
            return A, B
        A, B, _, _ = upper_lft_matrices(  # the plant rows of Fu: no output rows below v
            self.A_mid,
            np.hstack([self.B_d, self.B_mid]),
            self.C_v,
            np.hstack([self.D_vd, self.D_vu]),
            self.delta_matrix(delta, residual),
        )
        return np.real_if_close(A), np.real_if_close(B)

    def plant_at(self, delta, *, residual=None, strict: bool = True) -> control.StateSpace:
        """The plant ``G(δ) = (A(δ), B(δ), C, 0)``, MATLAB's ``usubs``.

        Examples
        --------
        >>> import numpy as np, polyrob
        >>> from polyrob.plant.uncertainty import uncertain_plant
        >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
        >>> unc = uncertain_plant(pldi, model="box")
        >>> G = unc.plant_at(-np.ones(unc.n_params))
        >>> bool(G.B[2, 0] == pldi.interval("b31")[0])
        True
        """
        return self._ss(*self.matrices_at(delta, residual=residual, strict=strict), "G")

    def residual_samples(self, n: int, seed=None) -> list:
        """``n`` random real residual blocks with ``‖R‖ = 1`` per full block (``[]`` each if none)."""
        rng = np.random.default_rng(seed)
        out = []
        for _ in range(int(n)):
            blocks = []
            for size in self.full_blocks:
                R = rng.standard_normal((size, size))
                blocks.append(R / np.linalg.norm(R, 2) * rng.uniform() ** (1.0 / (size * size)))
            out.append(blocks)
        return out

    def delta_samples(
        self, n: int | None = None, *, kind: str = "uniform", seed=None, max_corners: int = MAX_CORNERS
    ) -> np.ndarray:
        """Points ``δ`` of the parameter box, shape ``(n, n_params)``.

        ``kind="uniform"``: uniform in ``[-1, 1]^k``; ``kind="corners"``: all
        ``2^k`` corners (first parameter fastest) when ``n`` is None, ``n``
        random corners otherwise.  Raises :class:`~polyrob.errors.PolyrobError`
        on an unknown kind, a missing ``n`` or more corners than ``max_corners``.
        """
        k = self.n_params
        rng = np.random.default_rng(seed)
        if kind == "uniform":
            if n is None or int(n) < 0:
                raise ArgumentError("uniform δ sampling needs a number of samples n >= 0")
            return rng.uniform(-1.0, 1.0, size=(int(n), k))
        if kind == "corners":
            if n is not None:
                return rng.choice([-1.0, 1.0], size=(int(n), k))
            if 2**k > max_corners:
                raise ArgumentError(
                    f"{k} parameters have 2^{k} = {2**k} corners, more than max_corners={max_corners}; "
                    "raise max_corners or draw random corners with delta_samples(n, kind='corners')"
                )
            bits = (np.arange(2**k)[:, None] >> np.arange(k)[None, :]) & 1
            return 2.0 * bits - 1.0
        raise ArgumentError(f"unknown δ sampling kind '{kind}': use 'uniform' or 'corners'")

    def usample(self, n: int, seed=None, *, return_delta: bool = False):
        """``n`` plants at uniform random ``δ ∈ [-1, 1]^k`` (and random residual blocks), MATLAB's ``usample``."""
        deltas = self.delta_samples(n, kind="uniform", seed=seed)
        res = self.residual_samples(n, seed=None if seed is None else np.random.default_rng(seed).integers(2**31))
        systems = [self.plant_at(d, residual=r if r else None) for d, r in zip(deltas, res)]
        return (systems, deltas) if return_delta else systems

    def corners(self, max_corners: int = MAX_CORNERS, *, return_delta: bool = False):
        """The plants at all ``2^k`` corners ``δ ∈ {-1, 1}^k`` (full blocks at 0)."""
        deltas = self.delta_samples(kind="corners", max_corners=max_corners)
        systems = [self.plant_at(d) for d in deltas]
        return (systems, deltas) if return_delta else systems

    def with_figures(self, **figures) -> UncertainPlant:
        """A copy with ``coverage``, ``coverage_points``, ``volume_ratio`` or ``info`` replaced."""
        from dataclasses import replace

        return replace(self, **figures)
