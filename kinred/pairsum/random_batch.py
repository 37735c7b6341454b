r"""The random batch pair-sum backend (RBM): pair sums inside random batches of ``p`` agents.

:class:`RandomBatch` replaces every pair sum of a scene (the paper's class (1.1),
with ``f_ij = c_j φ(D)``)

.. math:: F_i = \sum_{j} c_j\, \varphi(\|s_i - s_j\|)\,(z_j - z_i)

by its random batch estimate (Jin, Li, Liu, *Random Batch Methods (RBM) for interacting
particle systems*, J. Comput. Phys. 400 (2020) 108877, Algorithm 1, "RBM-1"): at every
evaluation the agents are shuffled by a uniform random permutation and cut into consecutive
batches of ``p`` agents (the last batch holds the ``N mod p`` remaining agents when ``p``
does not divide ``N``), and each agent interacts only with the agents of its batch,

.. math:: \hat F_i = \frac{1}{q} \sum_{j \in \mathcal B(i),\, j \ne i} c_j\,
          \varphi(\|s_i - s_j\|)\,(z_j - z_i), \qquad
          q = \frac{\sum_b |\mathcal B_b|\,(|\mathcal B_b| - 1)}{N (N - 1)} .

Unbiasedness, for any coefficients ``c`` (weights, ``normalize="mean"`` or ``"sum"``): under a
uniform permutation the positions of two agents ``i ≠ j`` form a uniform ordered pair of
distinct positions, so ``P(j ∈ 𝓑(i)) = Σ_b |𝓑_b|(|𝓑_b| − 1) / (N(N − 1)) = q`` for *every*
pair, hence ``E F̂ᵢ = Σⱼ (q/q) cⱼ φᵢⱼ (zⱼ − zᵢ) = Fᵢ``. When ``p | N``, ``q = (p − 1)/(N − 1)``
and ``1/q`` is the ``(N − 1)/(p − 1)`` rescaling of Jin–Li–Liu; when ``p ∤ N`` the exact ``q``
keeps the estimate unbiased (the plain ``(N − 1)/(p − 1)`` would not be). Unequal weights
need no weighted sampling for unbiasedness (each pair is equally likely whatever ``c``); the
variance is then larger for heavy agents, a price paid only in the error constant.

Time stepping. The RBM is defined with one partition per time step: with the forward Euler
scheme of ``simulate`` (``method="euler"``, the paper's eq. (1.6)) one
evaluation is one step and this backend *is* RBM-1. Every evaluation draws a new partition,
so a multi-stage method (RK4, adaptive pairs) sees an independent, still unbiased, estimate in
each stage: that is not the published scheme and gains no order (the error stays
``O(√(h/(p − 1)))``); adaptive error control then measures sampling noise. Use Euler.
Euler's step can be taken inside the batches (:meth:`RandomBatch.euler_step`, which
``simulate`` uses): each batch's rows are read and written by that batch alone, so the
in-place update of a batch right after its sums is the step from the whole right-hand side,
bit for bit, with one pass over the state and no derivative arrays.

Error. For a fixed horizon the expected (mean-square) distance between the RBM trajectory
and the exact one (both with step ``h``) is ``O(√(h/(p − 1)))`` (Jin–Li–Liu, §3, for
contractive interactions; for Cucker–Smale alignment uniformly in time: S.-Y. Ha, S. Jin,
D. Kim, D. Ko, *Uniform-in-time error estimates for the random batch method for the
Cucker–Smale model*, Math. Models Methods Appl. Sci. 31 (2021); for first-order consensus: S.-Y. Ha, S. Jin, D. Kim, D. Ko, *Convergence
toward equilibrium of the first-order consensus model with random batch interactions*,
J. Differential Equations 302 (2021)). Measured in tests/test_pairsum_rbm.py (slope 0.51 of
the RMS trajectory error in ``h/(p − 1)``) and benchmarks/_bench_large_n_rbm.py. Averaged
observables converge faster: the error of ``Γ(t)`` measured there scales like ``h/(p − 1)``
(slope ≈ 1), the fluctuations of the agents averaging out.

Cost and memory. ``N(p − 1)/2`` pairs per evaluation, each ``O(d)``: ``O(N p d)`` time;
memory ``O(N·d)`` for the state and the results plus ``O(N)`` for the permutation and
``O(block)`` per thread — never ``N × N``.

Randomness. Every evaluation draws exactly ``rng.permutation(N)`` from the generator it is
given (the run's generator, which ``simulate`` derives from ``seed``; ensembles derive it from
the member seed), and nothing else: runs are reproducible by seed and ensembles bit-identical
across executors. Without a generator the backend refuses to run (``InvalidInput``): a hidden
default generator would make runs irreproducible or silently correlated.

Threads. Batches are grouped into fixed chunks of about ``block`` pairs (independent of the
thread count) and the chunks are dealt to the engine threads
(:func:`~kinred.dynamics.set_num_threads`); a chunk writes only rows of its own agents and
each agent's sum runs in a fixed order, so results are bit-identical for any thread count.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from .._validate import as_array, as_float, as_int
from .. import _parallel
from ..errors import InvalidInput
from . import _rbm_kernels, _rbm_step
from ._base import PairTerms, check_plan_args

__all__ = ["RandomBatch", "RandomBatchPlan", "pair_probability"]

#: Default pairs per chunk (the unit of work dealt to threads; 512 kB of float64 distances).
BLOCK = 65_536


def pair_probability(n: int, p: int) -> float:
    """``q = P(j ∈ batch(i))`` for any two agents ``i ≠ j`` of ``n`` under a uniform random
    partition into batches of ``p`` (the last batch of ``n mod p`` agents):
    ``Σ_b |𝓑_b|(|𝓑_b| − 1) / (n(n − 1))``.

    Examples
    --------
    >>> pair_probability(10, 5), pair_probability(10, 4)      # 4/9 ; (12 + 12 + 2)/90
    (0.4444444444444444, 0.28888888888888886)
    """
    n = as_int(n, "n", low=2)
    p = as_int(p, "p", low=2, high=n)
    nb, r = divmod(n, p)
    return (nb * p * (p - 1) + r * (r - 1)) / (n * (n - 1))


@dataclass(frozen=True, eq=False)
class RandomBatchPlan:
    """Everything :meth:`RandomBatch.evaluate` needs that depends only on the scene and the shape.

    Attributes
    ----------
    n, dim, p : int
    terms : PairTerms
    q : float
        The pair probability (``kinred.pairsum.random_batch.pair_probability``).
    cs : (n,) ndarray
        The coefficients divided by ``q``: ``cⱼ/q``.
    chunks : tuple of (int, int)
        Batch ranges ``[b0, b1)`` of about ``block`` pairs each (independent of threads).
    groups : tuple of tuple of (int, int)
        The chunks of each engine thread.
    max_pairs : int
        Pairs of the largest chunk (scratch size).
    by_source : tuple
        Per distance source: ``(source, ((term, value_sq or None), ...))`` in scene order.
    targets : tuple of str
    """

    n: int
    dim: int
    p: int
    terms: PairTerms
    q: float
    cs: np.ndarray
    chunks: tuple
    groups: tuple
    max_pairs: int
    by_source: tuple
    targets: tuple


class RandomBatch:
    """The random batch pair-sum backend (``pairsum="random_batch"`` for ``p = 2``).

    Parameters
    ----------
    p : int
        Batch size, ``p >= 2`` (``p = N``: one batch, the exact pair sums). Checked against
        the number of agents when a scene plans a state shape: ``p > N`` is refused there.
    block : int, optional
        Pairs per chunk of work (default 65 536); chunks are the unit dealt to threads.

    Notes
    -----
    Needs the run's generator at every evaluation (``Scene.rhs(..., rng=...)``; ``simulate``
    passes the one it derives from ``seed``); see the module docstring for the algorithm, the
    proof of unbiasedness, the error law and why Euler is the scheme to use.

    Examples
    --------
    >>> from kinred.dynamics import Alignment, CuckerSmale, Scene
    >>> sc = Scene([Alignment(CuckerSmale(1.0, 0.0))], pairsum=RandomBatch(p=2))
    >>> x, v = np.zeros((4, 1)), np.array([[1.0], [-1.0], [3.0], [-3.0]])
    >>> dv = sc.rhs(x, v, rng=np.random.default_rng(0))[1]
    >>> float(dv.sum())          # pairs exchange equal and opposite updates (equal weights)
    0.0
    """

    #: Pair sums run in float64.
    precision = "double"

    #: It draws from the run's generator: ``simulate`` passes it to every evaluation.
    stochastic = True

    #: Pair sums inside random batches approximate the full ones: certificates refuse it.
    exact = False

    #: ``evaluate`` writes into the caller's arrays when given ``out`` (see :class:`PairSum`).
    accepts_out = True

    def __init__(self, p: int = 2, block: int | None = None):
        self.p = as_int(p, "p", low=2)
        self.block = BLOCK if block is None else as_int(block, "block", low=1)

    def __repr__(self) -> str:
        extra = "" if self.block == BLOCK else f", block={self.block!r}"
        return f"RandomBatch(p={self.p!r}{extra})"

    # ------------------------------------------------------------------ plan
    def plan(self, scene, n: int, dim: int) -> RandomBatchPlan:
        """The plan of ``scene`` for states ``(n, dim)`` with the current engine threads.

        Raises
        ------
        InvalidInput
            ``p > n`` (a batch larger than the system).
        """
        terms, n, dim = check_plan_args(scene, n, dim)
        p = self.p
        if p > n:
            raise InvalidInput(f"RandomBatch(p={p}) needs p <= N, the number of agents; got "
                               f"N = {n} (valid: 2 <= p <= {n}; p = N gives the exact pair sums)")
        q = pair_probability(n, p) if n >= 2 else 1.0
        per = max(1, self.block // (p * (p - 1) // 2))
        nbt = -(-n // p)
        chunks = tuple((b0, min(b0 + per, nbt)) for b0 in range(0, nbt, per))
        nthreads = max(1, min(_parallel.get_num_threads(), len(chunks)))
        groups = tuple(tuple(g) for g in _rbm_step.split(chunks, nthreads))
        return RandomBatchPlan(
            n=n, dim=dim, p=p, terms=terms, q=q, cs=scene.coefficients(n) / q, chunks=chunks,
            groups=groups, max_pairs=max(_rbm_kernels.pairs_in(n, p, b0, b1) for b0, b1 in chunks),
            by_source=tuple((s, tuple((t, getattr(t.kernel, "value_sq", None))
                                      for t in terms.of_source(s))) for s in terms.sources),
            targets=tuple(sorted({t.target for t in terms.terms})))

    # ------------------------------------------------------------------ evaluate
    def evaluate(self, plan: RandomBatchPlan, x: np.ndarray, v: np.ndarray | None,
                 rng=None, out: dict | None = None) -> dict:
        """The random batch pair sums at ``(x, v)``: ``{target: (n, dim) ndarray}``, from one
        partition drawn as ``rng.permutation(n)``.

        ``out`` (optional): ``{target: array}`` of C-contiguous float64 ``(n, dim)`` arrays to
        overwrite and return instead of fresh ones (a loop that consumes the sums before the
        next evaluation saves the fresh pages of two state-sized arrays per step:
        :meth:`kinred.integrate.VectorField.transient`); the values are bit-identical.

        Raises
        ------
        InvalidInput
            A plan of another backend or shape, ``rng`` not a ``numpy.random.Generator``, or
            an ``out`` array of another shape or dtype.
        """
        if not isinstance(plan, RandomBatchPlan) or x.shape != (plan.n, plan.dim):
            raise InvalidInput(f"plan must be a RandomBatchPlan for states of shape (n, dim) = "
                               f"{getattr(plan, 'n', '?'), getattr(plan, 'dim', '?')}; got "
                               f"{type(plan).__name__} and x of shape {x.shape}")
        if not isinstance(rng, np.random.Generator):
            raise InvalidInput(
                f"RandomBatch needs the run's random generator, got rng={rng!r}: pass "
                "rng=numpy.random.default_rng(seed) to Scene.rhs (simulate passes the generator "
                "it derives from its seed), so that runs are reproducible by seed")
        perm = rng.permutation(plan.n)
        state = {"x": np.ascontiguousarray(x, dtype=np.float64),
                 "v": None if v is None else np.ascontiguousarray(v, dtype=np.float64)}
        outs = {tgt: _result_array(plan, out, tgt) for tgt in plan.targets}
        if out is not None:
            _check_distinct(outs, state)
        _parallel.run_parallel(partial(_share, plan, state, perm, outs), list(plan.groups))
        return outs

    def euler_step(self, plan: RandomBatchPlan, x: np.ndarray, v: np.ndarray | None,
                   h: float, rng, local: tuple, w: np.ndarray, shift: np.ndarray,
                   centres: np.ndarray) -> tuple:
        """Forward Euler's step (eq. (1.6)) with the pair sums of one partition, in place:
        ``x ← x + h·dx``, ``v ← v + h·dv`` with ``(dx, dv)`` the drift that
        :meth:`evaluate` (same ``rng`` draw) plus the scene's local drifts give, bit for bit,
        and the row sums of the new state for its moments, from one pass over the state
        (each batch's rows read, summed, updated and summed again while in cache: no result
        arrays, no second pass).

        ``v`` is given exactly when a term targets ``v`` (second-order scenes). ``local =
        (drifts of x, drifts of v)``: two sequences of ``(n, dim)`` arrays, added in their
        order (as ``Scene._rhs`` adds its local effects). ``w`` ``(n,)`` weights; ``shift``,
        ``centres`` ``(k, dim)`` (``k = 2`` with ``v``, else 1): the sums are those of
        ``kinred._rowsum_kernels.row_sums`` of ``x + shift[0]`` and ``v + shift[1]`` about
        ``centres``. Returns ``(r, acc)`` of shapes ``(k, dim)``, ``(k, 4)``, summed over
        fixed pieces in a fixed order (bit-identical for any thread count;
        ``kinred.pairsum._rbm_step``). A kernel that raises mid-step leaves the state
        partly stepped (the pieces other threads finished).

        Raises
        ------
        InvalidInput
            A plan of another backend or shape; ``rng`` not a Generator; ``h`` not a finite
            number; ``v`` given or missing against the plan's terms; state or local arrays
            that are not C-contiguous float64 ``(n, dim)`` (the state writeable, apart from
            every other array); ``w``, ``shift`` or ``centres`` not finite float arrays of
            the shapes above.
        """
        if not isinstance(plan, RandomBatchPlan):
            raise InvalidInput(f"plan must be a RandomBatchPlan, got {type(plan).__name__}")
        if not isinstance(rng, np.random.Generator):
            raise InvalidInput(f"RandomBatch needs the run's random generator, got rng={rng!r}")
        h = as_float(h, "h")
        shape, order2 = (plan.n, plan.dim), "v" in plan.targets
        if (v is not None) != order2:
            raise InvalidInput(f"v must be {'given' if order2 else 'None'} for this plan (its "
                               f"terms target {plan.targets}), got "
                               f"{'None' if v is None else type(v).__name__}")
        if (not isinstance(local, (tuple, list)) or len(local) != 2
                or not all(isinstance(g, (tuple, list)) for g in local)):
            raise InvalidInput(f"local must be a pair (drifts of x, drifts of v) of sequences of "
                               f"arrays, got {type(local).__name__}")
        arrays = [("x", x, True), ("v", v, True)] + [
            (f"local {t} drift {q}", a, False) for t, g in zip("xv", local)
            for q, a in enumerate(g)]
        for name, a, write in arrays:
            if a is not None and (type(a) is not np.ndarray or a.dtype != np.float64
                                  or a.shape != shape or not a.flags.c_contiguous
                                  or (write and not a.flags.writeable)):
                raise InvalidInput(f"{name} must be a C-contiguous float64 array of shape "
                                   f"{shape}{' (writeable)' if write else ''}, got "
                                   f"{type(a).__name__} {getattr(a, 'dtype', '')} "
                                   f"{getattr(a, 'shape', '')}")
        for i, (name, a, write) in enumerate(arrays):
            for other, b, _ in arrays[i + 1:]:
                if write and a is not None and b is not None and np.may_share_memory(a, b):
                    raise InvalidInput(f"{name} shares memory with {other}: the step writes "
                                       f"{name} while it reads {other}; pass copies")
        k = 2 if order2 else 1
        w = as_array(w, "w", shape=(plan.n,))
        shift = as_array(shift, "shift", shape=(k, plan.dim))
        centres = as_array(centres, "centres", shape=(k, plan.dim))
        return _rbm_step.euler_step(plan, x, v, h, rng.permutation(plan.n), local, w, shift,
                                    centres)


def _result_array(plan: RandomBatchPlan, out: dict | None, tgt: str) -> np.ndarray:
    """The array the sums of ``tgt`` are written to: ``out[tgt]`` when given (checked), else
    a fresh one (every row is cleared by its chunk before it is accumulated into)."""
    a = None if out is None else out.get(tgt)
    if a is None:
        return np.empty((plan.n, plan.dim))
    if (type(a) is not np.ndarray or a.dtype != np.float64 or a.shape != (plan.n, plan.dim)
            or not a.flags.c_contiguous or not a.flags.writeable):
        raise InvalidInput(f"out[{tgt!r}] must be a writeable C-contiguous float64 array of "
                           f"shape {(plan.n, plan.dim)}, got {type(a).__name__} "
                           f"{getattr(a, 'dtype', '')} {getattr(a, 'shape', '')}")
    return a


def _check_distinct(outs: dict, state: dict) -> None:
    """The result arrays may share no memory with each other nor with the state (the kernel
    clears rows of a result while it still reads the carriers)."""
    arrays = list(outs.items()) + [(f"the state's {k}", a) for k, a in state.items()
                                   if a is not None]
    for i, (name, a) in enumerate(arrays[:len(outs)]):
        for other, b in arrays[i + 1:]:
            if np.may_share_memory(a, b):
                raise InvalidInput(f"out[{name!r}] shares memory with "
                                   f"{other if other.startswith('the') else f'out[{other!r}]'}"
                                   "; give each target its own array, apart from x and v")


def _share(plan: RandomBatchPlan, state: dict, perm: np.ndarray, outs: dict, g: int,
           chunks) -> None:
    """Thread ``g``'s chunks: per chunk and source, the squared distances of the chunk's pairs,
    then per term its kernel values and the accumulation into the term's target."""
    qbuf = np.empty(plan.max_pairs)
    pbuf = np.empty(plan.max_pairs)
    n, p = plan.n, plan.p
    for b0, b1 in chunks:
        m = _rbm_kernels.pairs_in(n, p, b0, b1)
        if m == 0:      # a lone agent (N mod p = 1): no pair, its sums are 0
            for tgt in plan.targets:
                outs[tgt][perm[b0 * p:min(b1 * p, n)]] = 0.0
            continue
        cleared = set()
        # the last term of a source may overwrite the distances
        for t, phi in _rbm_step.term_values(
                plan, state, perm, b0, b1, qbuf[:m],
                lambda i, q, last: q if last else pbuf[:m]):
            _rbm_kernels.batch_accumulate(state[t.carrier], plan.cs, perm, p, b0, b1, phi,
                                          outs[t.target], t.target not in cleared)
            cleared.add(t.target)
