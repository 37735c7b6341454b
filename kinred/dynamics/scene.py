r"""Scenes: sums of effects; their pair sums are evaluated by a pluggable backend.

A :class:`Scene` is the vector field of the sum of its effects on the phase space ``(x, v)``
of ``N`` agents in ``ℝᵈ`` (second order, eq. (4.2)–(4.3)), or
on positions only (first order, :class:`~kinred.dynamics.Aggregation`).

Normalization
-------------
Pairwise sums carry coefficients ``c_j``:

* ``normalize="mean"``: ``c_j = w_j`` (``1/N`` without weights) – the paper's written
  formulas (2.13) and (3.14), and the mean-field form (4.3);
* ``normalize="sum"``: ``c_j = N w_j`` (coefficient 1 per agent without weights).

With ``weights`` (probability weights of a quantized measure) ``w_j`` replaces ``1/N``.
The paper's numerical experiments (§3.4.1, Table 1 pattern: flocking at β = 1.5, mostly at
1.62, not at 1.7) are reproduced with ``normalize="sum"`` and ``G = 0.8``; with
``normalize="mean"`` and ``G = 1`` that setting never flocks (Γ stays ≈ 66).

Pair sums
---------
The scene lists what its pairwise effects call for once, in :attr:`Scene.pair_terms` (a
:class:`~kinred.pairsum.PairTerms`: the terms, the distance sources and carriers needed,
the accumulators, the coefficients), and hands it to its backend (``pairsum=``, see
:mod:`kinred.pairsum`; default :class:`~kinred.pairsum.Dense`, exact blocked BLAS/numba).
The backend's plan is built once per state shape and engine threads and kept. Per-agent
effects are evaluated directly; a scene without pairwise effects costs ``O(N·d)`` per
evaluation.
"""

from __future__ import annotations

import threading
from typing import NamedTuple, Sequence

import numpy as np

from .._validate import as_array, as_choice, as_float, as_weights
from ..errors import InvalidInput, NotProjectable
from ..pairsum import PairTerms, as_pairsum
from ..projection import as_projection
from .. import _parallel
from .effects import Effect

__all__ = ["Scene", "ProjectedSystem", "project_state"]

#: Plans kept per scene (e.g. a few shapes or thread counts in one session).
_PLANS_KEEP = 4
#: Guards every scene's plan cache (plans are built rarely; a lock per scene would not pickle).
_PLANS_LOCK = threading.RLock()


class ProjectedSystem(NamedTuple):
    """The projected system and its initial state, from :meth:`Scene.projected`.

    A named tuple: ``scene_k, y0, w0 = scene.projected(M, x0, v0)`` or
    ``simulate(*scene.projected(M, x0, v0), t_span, dt)``.

    Attributes
    ----------
    scene : Scene
        The projected scene on ``ℝᵏ`` (eq. (2.4)–(2.5), eq. (3.5)).
    y0 : (N, k) ndarray
        ``M x⁰`` row-wise.
    w0 : (N, k) ndarray or None
        ``M v⁰`` row-wise; None for a first-order scene.
    """

    scene: "Scene"
    y0: np.ndarray
    w0: np.ndarray | None


class Scene:
    """The vector field of a sum of effects.

    Parameters
    ----------
    effects : sequence of Effect
        The terms (see :class:`kinred.dynamics.Effect` and its subclasses).
    normalize : {"mean", "sum"}
        Pairwise coefficients ``c_j = w_j`` or ``N w_j`` (see the module notes; ``"sum"``
        with ``G = 0.8`` reproduces the paper's §3.4 experiments).
    weights : (N,) array_like, optional
        Probability weights of the agents (validated: finite, >= 0, sum 1); default ``1/N``.
    pairsum : PairSum or str, optional
        The pair-sum backend (:mod:`kinred.pairsum`): an object implementing
        :class:`~kinred.pairsum.PairSum`, or a name of the registry
        :data:`kinred.pairsum.PAIRSUMS` (the names scene files accept too): ``"fast"``/
        ``"dense"`` (default) for :class:`~kinred.pairsum.Dense` (exact, blocked BLAS/numba),
        ``"numpy"`` for the plain-numpy twin :class:`~kinred.pairsum.Numpy` (reference and
        tests), ``"auto"``, ``"nufft"``, ``"cells"``, ``"random_batch"``, and any backend
        added with :func:`kinred.pairsum.register_pairsum`.
    block : int, optional
        ``Dense(block=...)``: rows per strip (default: strips of about 64k pairwise entries).
    engine : {"fast", "dense", "numpy"}, optional
        Older name of ``pairsum`` (give one of them).
    precision : {"double", "mixed"}, optional
        ``Dense(precision=...)``: ``"double"`` (default) computes everything in float64;
        ``"mixed"`` runs the pair sums in float32 with the state, the centring and the
        integrator in float64, an error relative to the *fluctuation* size (see
        :class:`~kinred.pairsum.Dense` and docs/dynamics.md for its measured accuracy).

    Attributes
    ----------
    order : int
        2 (state ``(x, v)``) or 1 (state ``x`` only).
    stochastic : bool
        True if any effect is noise.
    pairsum : PairSum
        The backend (shared with :meth:`project` and weighted copies).
    pair_terms : PairTerms
        What the pairwise effects call for (computed once).
    precision : str
        The backend's precision (``"double"`` for backends without one).

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> scene = Scene([Alignment(kernel=CuckerSmale(G=1.0, beta=0.0))], normalize="mean")
    >>> x = np.array([[0.0], [1.0]]); v = np.array([[1.0], [-1.0]])
    >>> dx, dv = scene.rhs(x, v)
    >>> dv.ravel()          # (1/2)·(v_j − v_i)
    array([-1.,  1.])
    """

    def __init__(self, effects: Sequence[Effect], normalize: str = "mean", weights=None, *,
                 pairsum=None, block: int | None = None, engine: str | None = None,
                 precision: str | None = None):
        if isinstance(effects, Effect) or not hasattr(effects, "__iter__"):
            effects = [effects]
        try:
            effects = tuple(effects)
        except TypeError:  # a 0-d array has __iter__ but cannot be iterated
            raise InvalidInput(f"effects must be a sequence of Effects, got {effects!r}") from None
        if not effects:
            raise InvalidInput("effects must contain at least one effect, got an empty sequence")
        for i, e in enumerate(effects):
            for attr in ("target", "pairwise", "projectable", "translation_invariant", "stochastic"):
                if not hasattr(e, attr):
                    raise InvalidInput(
                        f"effects[{i}] = {e!r} is not an Effect: it lacks the attribute {attr!r} "
                        "(see kinred.dynamics.Effect)")
        self.effects = effects
        self.normalize = as_choice(normalize, "normalize", ("mean", "sum"))
        if weights is not None:
            weights = as_array(weights, "weights", ndim=1)
            weights = as_weights(weights, "weights", len(weights))
        self.weights = weights
        self.pairsum = as_pairsum(pairsum, engine=engine, block=block, precision=precision)
        targets = {e.target for e in effects}
        if "x" in targets:
            bad = [e for e in effects if e.target == "v"]
            if bad:
                raise InvalidInput(
                    f"a scene mixes first-order effects (target 'x', e.g. Aggregation) with "
                    f"second-order ones (target 'v'): {bad!r}; use one kind")
            self.order = 1
        else:
            self.order = 2
        for e in effects:
            if e.pairwise and self.order == 1 and (e.source == "v" or e.carrier == "v"):
                raise InvalidInput(f"{e!r} needs velocities, which a first-order scene has not")
        self.stochastic = any(e.stochastic for e in effects)
        self.translation_invariant = all(e.translation_invariant for e in effects)
        self.pair_terms = PairTerms.from_effects(effects, self.order, self.normalize)
        self._local = [e for e in effects if not e.pairwise and not e.stochastic]
        self._noise = [e for e in effects if e.stochastic]
        self._plans: dict = {}

    # ------------------------------------------------------------------ helpers
    @property
    def precision(self) -> str:
        """The backend's precision: ``"double"``, ``"mixed"`` (``"double"`` if it has none)."""
        return getattr(self.pairsum, "precision", "double")

    def _tgt(self, e) -> str:
        return e.target if e.target is not None else ("v" if self.order == 2 else "x")

    def agent_weights(self, n: int) -> np.ndarray:
        """Probability weights ``(n,)`` of the agents (uniform when none were given)."""
        if self.weights is None:
            return np.full(n, 1.0 / n)
        if self.weights.shape[0] != n:
            raise InvalidInput(f"the scene has {self.weights.shape[0]} weights but the state has "
                               f"{n} agents")
        return self.weights

    def coefficients(self, n: int) -> np.ndarray:
        """Pairwise coefficients ``c_j``: ``w_j`` (mean) or ``N w_j`` (sum), shape ``(n,)``."""
        return self.pair_terms.coefficients(self.agent_weights(n))

    def _plan(self, n: int, dim: int):
        """The backend's plan for states ``(n, dim)`` and the current engine threads (kept)."""
        key = (n, dim, _parallel.get_num_threads())
        plan = self._plans.get(key)  # one dict read: atomic, the hot path takes no lock
        if plan is None:
            with _PLANS_LOCK:  # two threads simulating this scene: one builds, one evicts
                plan = self._plans.get(key)
                if plan is None:
                    plan = self.pairsum.plan(self, n, dim)
                    while len(self._plans) >= _PLANS_KEEP:
                        self._plans.pop(next(iter(self._plans)), None)
                    self._plans[key] = plan
        return plan

    def _check_state(self, x, v, names=("x", "v"), finite=True):
        """The validated state; ``names`` name the arguments in messages (``x0, v0``).
        ``finite=False`` leaves the NaN/Inf test to the caller (``simulate`` takes it from the
        sums of its first compiled pass over the state, see ``kinred.integrate._simulate``)."""
        nx, nv = names
        x = as_array(x, nx, ndim=2, finite=finite)
        if x.shape[0] < 1 or x.shape[1] < 1:
            raise InvalidInput(f"{nx} must have at least one agent and one dimension, got {x.shape}")
        if self.order == 2:
            if v is None:
                raise InvalidInput(f"{nv} must be given for a second-order scene (order 2)")
            v = as_array(v, nv, ndim=2, finite=finite)
            if v.shape != x.shape:
                raise InvalidInput(f"{nv} must have the shape of {nx}, {x.shape}, got {v.shape}")
        elif v is not None:
            raise InvalidInput(f"{nv} must be None for a first-order scene (order 1), got an array")
        if self.weights is not None:
            self.agent_weights(x.shape[0])
        return x, v

    # ------------------------------------------------------------------ the field
    def rhs(self, x, v=None, t: float = 0.0, *, rng=None):
        """The drift ``(dx, dv)`` (without noise effects).

        Parameters
        ----------
        x, v : (N, d) ndarray
            State; ``v`` must be None for first-order scenes.
        t : float
        rng : numpy.random.Generator, optional
            Randomness for a stochastic pair-sum backend; exact backends ignore it.

        Returns
        -------
        dx : (N, d) ndarray
        dv : (N, d) ndarray or None (order 1)
        """
        x, v = self._check_state(x, v)
        t = as_float(t, "t")
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise InvalidInput(f"rng must be a numpy.random.Generator or None, got {rng!r}")
        dx, dv = self._rhs(x, v, t, rng)
        if self.order == 2 and dx is v:
            dx = v.copy()
        return dx, dv

    def _rhs(self, x, v, t, rng=None, out=None):
        """Unvalidated drift; for order 2 ``dx`` is ``v`` itself (no copy). ``rng`` goes to
        stochastic pair-sum backends; ``out`` (``{target: array}``, for a backend that
        ``accepts_out`` only) receives the pair sums instead of fresh arrays."""
        n = x.shape[0]
        dv = dxe = None   # arrays owned by this call (fresh pairwise results, or ``out``'s)
        if self.pair_terms and n > 1:
            plan = self._plan(n, x.shape[1])
            if out is None:
                contrib = self.pairsum.evaluate(plan, x, v, rng)
            else:
                contrib = self.pairsum.evaluate(plan, x, v, rng, out=out)
            dv = contrib.get("v")
            dxe = contrib.get("x")
        for e in self._local:
            f = e.drift(x, v, t)
            if self._tgt(e) == "v":
                if dv is None:
                    dv = np.array(f, dtype=float)
                else:
                    dv += f
            elif dxe is None:
                dxe = np.array(f, dtype=float)
            else:
                dxe += f
        if self.order == 2:
            if dv is None:
                dv = np.zeros_like(v)
            dx = v if dxe is None else v + dxe
        else:
            dv = None
            dx = np.zeros_like(x) if dxe is None else dxe
        return dx, dv

    def _euler_fused(self, x, v, t, h, rng, w, shift, centres):
        """Forward Euler's step in place by the pair-sum backend's fused step (a backend with
        ``euler_step``, e.g. :meth:`kinred.pairsum.RandomBatch.euler_step`), the local drifts
        evaluated first at the old state (each used as it comes when it is a C-contiguous
        float64 ``(N, d)`` array apart from the state, else copied): ``(r, acc)``, the row
        sums of the new state for its moments; None (nothing done) when the backend has no
        fused step or the scene no pair sums. The new state equals ``_rhs`` and the update
        bit for bit (the local drifts are added in the scene's order)."""
        step = getattr(self.pairsum, "euler_step", None)
        n = x.shape[0]
        if step is None or not self.pair_terms or n < 2:
            return None
        plan = self._plan(n, x.shape[1])
        local = {"x": [], "v": []}
        for e in self._local:
            f = e.drift(x, v, t)
            if (type(f) is not np.ndarray or f.dtype != np.float64 or f.shape != x.shape
                    or not f.flags.c_contiguous or np.may_share_memory(f, x)
                    or (v is not None and np.may_share_memory(f, v))):
                f = np.array(np.broadcast_to(np.asarray(f, dtype=float), x.shape), order="C")
            local[self._tgt(e)].append(f)
        return step(plan, x, v, h, rng, (tuple(local["x"]), tuple(local["v"])), w, shift,
                    centres)

    def info(self) -> dict:
        """What the scene's pair sums run on: ``{"backend": repr, "pairsum": ...}`` with the
        ``info()`` of its most recent plan when the backend's plans have one (e.g. the
        choice of ``pairsum="auto"`` and its cost estimates, NUFFT's grids, the cell list's
        cutoffs), else None.

        Examples
        --------
        >>> from kinred.dynamics import Alignment
        >>> Scene([Alignment()]).info()
        {'backend': 'Dense()', 'pairsum': None}
        """
        last = next(reversed(self._plans.values()), None) if self._plans else None
        fn = getattr(last, "info", None)
        return {"backend": repr(self.pairsum), "pairsum": fn() if callable(fn) else None}

    def noise_increment(self, rng, n: int, dim: int, dt: float):
        """``(ΔX, ΔV)`` of all noise effects over a step ``dt`` (None where absent)."""
        dX = dV = None
        for e in self._noise:
            inc = e.increment(rng, n, dim, dt)
            if self._tgt(e) == "v":
                dV = inc if dV is None else dV + inc
            else:
                dX = inc if dX is None else dX + inc
        return dX, dV

    # ------------------------------------------------------------------ projection
    def project(self, M) -> "Scene":
        """The projected system (eq. (2.4)–(2.5); eq. (3.5)).

        Pairwise kernels see projected distances, per-agent ``fᵢ`` terms are multiplied by
        ``M``. Effects outside the paper's class (1.1) raise
        :class:`~kinred.errors.NotProjectable`.

        Parameters
        ----------
        M : (k, d) ndarray or Projection

        Returns
        -------
        Scene
            On ``ℝᵏ``; start it from :meth:`project_state`, or get both from :meth:`projected`.

        Examples
        --------
        >>> from kinred.dynamics import Scene, Alignment, Field
        >>> Scene([Alignment()]).project(np.eye(2, 3)).order
        2
        >>> Scene([Field(lambda t, x, v: np.sin(x))]).project(np.eye(2, 3))
        Traceback (most recent call last):
        ...
        kinred.errors.NotProjectable: Field('<lambda>') is a general per-agent field, ...
        """
        P = as_projection(M)
        new = []
        for e in self.effects:
            if not getattr(e, "projectable", False):
                try:
                    pe = e.project(P)
                except NotProjectable:
                    raise
                else:
                    raise NotProjectable(f"{e!r} declares projectable=False but project() returned "
                                         f"{pe!r}")
            new.append(e.project(P))
        sc = Scene(new, normalize=self.normalize, weights=self.weights, pairsum=self.pairsum)
        sc.projection = P
        return sc

    def project_state(self, M, x0, v0=None):
        """Initial state of the projected system: ``(M x⁰, M v⁰)`` (``v0`` None for order 1)."""
        return project_state(M, x0, v0)

    def projected(self, M, x0, v0=None) -> ProjectedSystem:
        """The projected scene and its initial state in one call: :meth:`project` and
        :meth:`project_state` with the same ``M``.

        The system (2.4)–(2.5) (eq. (3.5) in continuous time) started from
        ``y⁰ = M x⁰``, ``w⁰ = M v⁰`` row-wise.

        Parameters
        ----------
        M : (k, d) ndarray or Projection
        x0 : (N, d) array_like
            Initial positions in ``ℝᵈ``.
        v0 : (N, d) array_like or None
            Initial velocities: required for a second-order scene, None for a first-order one.

        Returns
        -------
        ProjectedSystem
            The named tuple ``(scene, y0, w0)``; ``w0`` is None for a first-order scene.

        Raises
        ------
        InvalidInput
            ``x0`` not ``(N, d)`` with ``d`` the source dimension of ``M``, ``v0`` missing
            (order 2), given (order 1) or of another shape than ``x0``, or ``N`` different
            from the scene's number of weights.
        NotProjectable
            An effect outside the paper's class (1.1), as for :meth:`project`.

        Examples
        --------
        >>> from kinred.dynamics import Scene, Alignment
        >>> p = Scene([Alignment()]).projected(np.eye(1, 2), [[1.0, 2.0]], [[3.0, 4.0]])
        >>> p.scene.order, p.y0, p.w0
        (2, array([[1.]]), array([[3.]]))
        """
        P = as_projection(M)
        x0 = as_array(x0, "x0", ndim=2)
        if x0.shape[0] < 1 or x0.shape[1] != P.d:
            raise InvalidInput(
                f"x0 must have shape (N, {P.d}) with N >= 1 (d = {P.d}, the source dimension "
                f"of M of shape {P.shape}), got {x0.shape}")
        if self.order == 2 and v0 is None:
            raise InvalidInput("v0 must be given for a second-order scene (order 2), got None")
        if self.order == 1 and v0 is not None:
            raise InvalidInput("v0 must be None for a first-order scene (order 1), got an array")
        if self.weights is not None:
            self.agent_weights(x0.shape[0])
        scene = self.project(P)
        y0, w0 = project_state(P, x0, v0)
        return ProjectedSystem(scene, y0, w0)

    def __repr__(self) -> str:
        w = "None" if self.weights is None else f"<{self.weights.shape[0]}>"
        ps = "" if repr(self.pairsum) == "Dense()" else f", pairsum={self.pairsum!r}"
        return f"Scene({list(self.effects)!r}, normalize={self.normalize!r}, weights={w}{ps})"


def project_state(M, x0, v0=None):
    """``(M x⁰, M v⁰)`` row-wise (eq. (2.4)).

    Parameters
    ----------
    M : (k, d) ndarray or Projection
    x0 : (N, d) array_like
    v0 : (N, d) array_like or None

    Returns
    -------
    y0 : (N, k) ndarray
    w0 : (N, k) ndarray or None

    Examples
    --------
    >>> y0, w0 = project_state(np.eye(1, 2), [[1.0, 2.0]], [[3.0, 4.0]])
    >>> y0, w0
    (array([[1.]]), array([[3.]]))
    """
    P = as_projection(M)
    x0 = as_array(x0, "x0", ndim=2)
    if x0.shape[1] != P.d:
        raise InvalidInput(f"x0 must have {P.d} columns (d, the source dimension of M of "
                           f"shape {P.shape}), got shape {x0.shape}")
    y0 = P.apply(x0)
    w0 = None if v0 is None else P.apply(as_array(v0, "v0", shape=x0.shape))
    return y0, w0
