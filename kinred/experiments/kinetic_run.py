r"""The ``kinred run`` study: a scene file → kinetic and reduced solutions → W1, bound, report.

A scene file (TOML; schema, loader and :class:`~kinred.scenefile.Config` in
:mod:`kinred.scenefile`, reference in ``docs/scene-file.md``) gives the effects, the initial
phase-space measure, the quantization (``eps`` or ``atoms``), the projections (``k`` values,
kind), the integrator and the outputs. :func:`run` then

1. quantizes ``μ₀`` and solves the weighted particle system: ``μᴺ(t)``
   (:func:`kinred.kinetic.solve`; stage ``solve``);
2. optionally solves a finer reference ``μᴺ′(t)`` (stage ``reference``);
3. for every ``k``: draws ``M`` (seed ``member_seed(projection.seed, k)``), solves the reduced
   system ``νᴺ(t)``, computes ``W1(M#μᴺ(t), νᴺ(t))`` exactly, Theorem 4.3's bound with the
   proof's constants, the certificate of the reduced run when ``[certify]`` asks for it or it
   is cheap (:mod:`kinred.experiments.kinetic_certify`: certified bounds of the projection
   error and of Theorem 4.3's middle term), the reference estimate and the flocking /
   milling observables (stage ``k{k}``);
4. writes ``results.npz`` and ``summary.json`` (the run's numbers: the run is complete),
   then the figures and ``report.html`` (:mod:`kinred.experiments.kinetic_report`). Each
   figure is drawn in a guarded call (:func:`kinred.report.draw_figure`): a figure that cannot
   be drawn is replaced by a note in the report, never loses the run.

The stages live in a :class:`kinred.io.StageStore` in ``OUT/stages`` (index ``config.json``
with the hash of the resolved configuration, one ``.npz`` per stage written as soon as it is
computed): ``resume=True`` loads the finished stages and computes only the missing ones; a
folder holding a run of another configuration, or any run without ``resume``, is refused
(:class:`~kinred.errors.StoreMismatch`); a damaged stage file is named in a
:class:`~kinred.errors.KinredWarning` and recomputed; a damaged ``stages/config.json`` is
refused (:class:`~kinred.errors.DamagedFile`). Random draws of the dynamics (a random-batch
pair sum) come from the scene's ``seed``: stage ``solve`` uses ``member_seed(seed, 0)``, the
reference ``member_seed(seed, 1)``, and each reduced run the seed of the solution it reduces.

Each k stage is a :class:`KStage`, whose fields carry their label (:data:`LABELS`):
measured, certified bound, a-priori bound (the paper's constants) or estimate;
``summary.json`` carries the labels.

:class:`~kinred.scenefile.Config`, :func:`~kinred.scenefile.load_config` and
:func:`~kinred.scenefile.config_from_dict` are importable from here too.
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._repr import result_repr
from .._rng import member_seed
from ..errors import InvalidInput, KinredWarning
from ..scenefile import SMALL_SCENE, Config, config_from_dict, load_config  # noqa: F401
from . import kinetic_certify as _cert
from . import kinetic_report
from ._kinetic_stage import LABELS as _LABELS
from ._kinetic_stage import NOT_NUMBERS as _NOT_NUMBERS
from ._kinetic_stage import KStage

__all__ = ["KStage", "LABELS", "NOT_NUMBERS", "RunResult", "SharedStages", "run",
           "write_outputs"]


# ------------------------------------------------------------------------------------------
# the study
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunResult:
    """What a run produced (also on disk in ``out_dir``).

    Attributes
    ----------
    config : Config
    t : (T,) ndarray
    n_atoms, eps : int, float
    per_k : dict
        ``{k: KStage}``: the arrays of each k stage (:class:`KStage`: each field with what
        it is; also a mapping, ``per_k[k]["w1"]``), the same on a first run and on resume.
    high : dict
        ``gamma``, ``milling`` of ``μᴺ(t)``; ``diameter`` (an upper bound of the diameter of
        ``supp μᴺ(t)`` in ``ℝ²ᵈ``, O(N·d)) and ``diameter_lower`` (a distance between two
        atoms); its atoms at T, ``x_final``, ``v_final``, ``weights`` (for the report);
        ``w1_quantization`` with a reference.
    stages : dict
        ``{stage: "computed" | "loaded" | "shared"}`` (shared: taken from another run's folder,
        ``share_from`` of :func:`run`).
    wall_time : float
    out_dir : Path or None
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    config: Config
    t: np.ndarray
    n_atoms: int
    eps: float
    per_k: dict
    high: dict
    stages: dict
    wall_time: float
    out_dir: Path | None

    def table(self):
        """The per-k summary table (a :class:`kinred.report.Table`), every column labelled:
        measured ``W1(T)``, its certified bound and the worst ratio certified/measured over
        ``t ≥ 1``, Theorem 4.3's a-priori bound (``vacuous`` when above the diameter of the
        cloud), the reference estimate when there is one, the observables."""
        from ..report import Table

        cfg, ref = self.config, "w1_reference" in next(iter(self.per_k.values()))
        g_high = self.high["gamma"][-1]
        rows = [[f"d={cfg.d}", "", "", "", ""] + ([""] if ref else [])
                + [f"{g_high:.3g}", _verdict(g_high, cfg), f"{self.high['milling'][-1]:.3f}"]]
        notes = []
        for k, r in self.per_k.items():
            cert = float(r["cert_w1"][-1])
            ratio = _cert.worst_ratio(r["cert_w1"], r["w1"], self.t)
            b = float(r["bound"][-1])
            w1 = (float(r["w1"][-1]) if bool(r["exact"][-1])
                  else f"[{float(r['lower'][-1]):.4g}, {float(r['upper'][-1]):.4g}] (certified, "
                       f"gap {100 * _rel_gap(r)[-1]:.2g} %)")
            row = [f"k={k}", w1, cert if np.isfinite(cert) else "not certified",
                   ratio if np.isfinite(ratio) else "–",
                   f"{b:.3g}" + (" (vacuous)" if bool(r["vacuous"][-1]) else "")]
            if ref:
                row.append(float(r["w1_reference"][-1]))
            rows.append(row + [f"{r['gamma'][-1]:.3g}", _verdict(r["gamma"][-1], cfg),
                               f"{r['milling'][-1]:.3f}"])
            note = str(r["cert_note"])
            if not note.startswith("certified"):
                notes.append(f"k={k}: {note}")
        exact = all(bool(r["exact"][-1]) for r in self.per_k.values())
        head = ["system", "W1(T) measured" if exact else "W1(T) measured or [bracket]",
                "W1(T) certified bound",
                "certified/measured, max t≥1", "eq. (4.17)(T) a-priori bound"]
        head += ["W1(μ_M,ν)(T) estimate"] if ref else []
        head += ["Γ(T) measured", "verdict", "milling(T) measured"]
        how = ("exact (POT: dense LP, or beyond a few thousand atoms the sparse network simplex "
               "proved optimal by its dual)" if exact else
               "exact (POT, dense or sparse), or a certified bracket [lower, upper] where the "
               "sparse method did not close in its time budget (lower: c-transform of its duals, "
               "upper: its plan) or no linear program is solved (max-sliced lower bound, "
               "index-coupling upper bound)")
        cap = (f"W1 = W1(M#μᴺ(t), νᴺ(t)), {how}; its certified bound bounds the coupling "
               f"Σᵢ wᵢ|(yᵢ, wᵢ) − M(xᵢ, vᵢ)| ≥ W1 (kinred.certify); the a-priori bound is eq. "
               f"(4.17) with the proof's constants, vacuous where it exceeds the diameter of "
               f"supp μᴺ (≤ {float(self.high['diameter'][-1]):.3g} at T); N = {self.n_atoms}, "
               f"ε = {self.eps:.4g}, T = {cfg.t_final:g}")
        if ref:
            cap += f"; estimate: with a reference of N' = {self.high['n_atoms_reference']} atoms"
        if notes:
            cap += ". " + "; ".join(notes)
        return Table(head, rows, caption=cap)


def _rel_gap(r) -> np.ndarray:
    """``(upper − lower)/upper`` of the W1 bracket per saved time (0 where exact)."""
    lo, up = np.asarray(r["lower"], float), np.asarray(r["upper"], float)
    gap = np.where(up > 0, (up - lo) / np.where(up > 0, up, 1.0), 0.0)
    return np.where(np.asarray(r["exact"], bool), 0.0, gap)


def _verdict(g, cfg):
    from ..observables import flocking_verdict

    return flocking_verdict(float(max(g, 0.0)), yes_below=cfg.yes_below, no_above=cfg.no_above)


#: Arrays of a solve / reference stage file (a file missing one is damaged; those of a k stage
#: file: ``KStage.keys_for``).
_SOL_KEYS = ("t", "x", "v", "weights", "eps", "n_atoms", "quantize_time", "simulate_time",
             "gamma", "milling")

#: What every number of a run is (the fields of :class:`KStage` and the arrays of ``high``):
#: "measured", "certified bound", "a-priori bound" (the paper's constants) or "estimate".
#: Not numbers: :data:`NOT_NUMBERS`.
LABELS = _LABELS
#: Stage entries that are not numbers: the target dimension, the certificate's note and the
#: reference's atom count (parameters and text).
NOT_NUMBERS = _NOT_NUMBERS

#: Seed index of the solve and reference stages: ``member_seed(cfg.seed, index)``.
_SEEDS = {"solve": 0, "reference": 1}


def _loader(keys):
    """Reads a stage file that must hold ``keys`` (:meth:`StageStore.get_or_compute`)."""
    from ..io import read_npz

    return lambda path: read_npz(path, what="stage file", keys=keys)


def _solve_stage(cfg: Config, atoms, eps, seed):
    from ..kinetic import solve

    mu0 = cfg.initial_measure()
    sol = solve(cfg.scene(), mu0, eps=eps, atoms=atoms, t_span=(0.0, cfg.t_final), dt=cfg.dt,
                method=cfg.method, times=cfg.times(), rule=cfg.rule, max_atoms=cfg.max_atoms,
                seed=seed)
    return sol


def _sol_arrays(sol):
    from ..kinetic import milling_index
    from ..observables import gamma

    g = np.array([gamma(sol.v[i], sol.weights) for i in range(len(sol.t))])
    m = np.array([milling_index(sol.x[i], sol.v[i], sol.weights) for i in range(len(sol.t))])
    return dict(t=sol.t, x=sol.x, v=sol.v, weights=sol.weights, eps=sol.eps, n_atoms=sol.n_atoms,
                quantize_time=sol.quantize_time, simulate_time=sol.simulate_time, gamma=g,
                milling=m)


def _sol_from_arrays(a, cfg: Config, seed):
    from ..kinetic import KineticSolution, weighted_scene

    return KineticSolution(t=a["t"], x=a["x"], v=a["v"], weights=a["weights"], eps=float(a["eps"]),
                           n_atoms=int(a["n_atoms"]), quantization=None,
                           quantize_time=float(a["quantize_time"]),
                           simulate_time=float(a["simulate_time"]),
                           scene=weighted_scene(cfg.scene(), a["weights"]), method=cfg.method,
                           dt=cfg.dt, seed=seed)


def _solution(stages, shared, cfg: Config, name: str, atoms, eps):
    """``(arrays, KineticSolution)`` of stage ``solve`` or ``reference``."""
    seed = member_seed(cfg.seed, _SEEDS[name])
    a = _stage(stages, shared, name,
               lambda: _sol_arrays(_solve_stage(cfg, atoms, eps, seed)), _SOL_KEYS)
    return a, _sol_from_arrays(a, cfg, seed)


def _stage(stages, shared, name: str, compute, keys):
    """Stage ``name``: loaded (resume), taken from ``shared`` (:class:`SharedStages` or None)
    or computed."""
    taken = []

    def share_or_compute():
        got = None if shared is None else shared.get(name, keys)
        if got is not None:
            taken.append(name)
            return got
        return compute()

    value = stages.get_or_compute(name, share_or_compute, load=_loader(keys))
    if taken:
        stages.status[name] = "shared"
    return value


class SharedStages:
    """The stages of another result folder of the same scene that a run may take as its own.

    A stage file of ``folder/stages`` is taken when its digest (the array ``__digest__``, see
    :class:`kinred.io.StageStore`) is that of ``cfg`` up to the ``[certify]`` keys ``enabled``
    and ``norm`` (which do not change what a solve stage holds, nor a k stage that certified:
    :func:`kinred.experiments.kinetic_certify.certify_stage` computes the same certificate
    whether it was asked for or chosen because it is cheap), and, for a k stage, when it holds
    a certificate. Anything else (absent, damaged, of another configuration, not certified) is
    computed. Files are read, never written nor locked (they are written atomically).
    """

    def __init__(self, folder, cfg: Config):
        import dataclasses

        from ..scenefile import CertifyOptions

        self.folder = Path(folder)
        self.digests = {dataclasses.replace(cfg, certify=CertifyOptions(e, n, cfg.certify.paper))
                        .digest() for e in (None, True, False) for n in ("both", "rms", "max")}

    def __repr__(self) -> str:
        return f"SharedStages({str(self.folder)!r})"

    def get(self, name: str, keys):
        """The arrays of stage ``name`` if they can be taken (without ``__digest__``), else None."""
        from ..errors import KinredError
        from ..io import STAGE_DIGEST, read_npz

        path = self.folder / "stages" / f"{name}.npz"
        if not path.is_file():
            return None
        try:
            a = read_npz(path, what="stage file", keys=keys + (STAGE_DIGEST,))
        except KinredError:
            return None
        if str(a.pop(STAGE_DIGEST)) not in self.digests:
            return None
        if name.startswith("k") and not str(a["cert_note"]).startswith("certified"):
            return None
        return a


def _check_reference(cfg: Config, n_atoms: int) -> None:
    """Refuse a reference that is not finer than the run's ``N`` (``eps`` scenes: known only
    once the solve stage has quantized; ``atoms`` scenes are refused by the loader)."""
    from ..errors import ConfigError

    if cfg.reference_atoms <= n_atoms:
        raise ConfigError(f"{cfg.source}: quantize.reference_atoms: the reference must be finer "
                          f"than the run's quantization, N = {n_atoms} atoms; got "
                          f"reference_atoms = {cfg.reference_atoms} (valid: > {n_atoms})")


def _k_stage(cfg: Config, k: int, sol, ref, decision, diameter, quantization=None) -> KStage:
    """Stage ``k{k}``: the reduced run, W1, Theorem 4.3's bound, the certificate, observables."""
    from ..kinetic import compare, milling_index, reduce, reference_estimate, theorem_bound
    from ..observables import gamma
    from ..projection import jl_matrix

    M = jl_matrix(k, cfg.d, kind=cfg.kind, seed=member_seed(cfg.projection_seed, k))
    t0 = time.perf_counter()
    red = reduce(sol, M=M)
    c = compare(sol, red)
    tb = theorem_bound(sol, red)
    T = len(sol.t)
    out = dict(k=k, w1=c.w1, exact=c.exact, lower=c.lower, upper=c.upper, coupling=c.coupling,
               uniform=c.uniform, term_jl=tb.term_jl, term_quant=tb.term_quant, bound=tb.bound,
               bound_stated=tb.bound_stated, C=tb.C, D_eps=tb.D_eps, eps_jl=tb.eps_jl,
               alpha=tb.alpha, beta=tb.beta, Lp=tb.Lp, Lpp=tb.Lpp, Lambda=tb.Lambda,
               norm_M=tb.norm_M, L=tb.L,
               gamma=np.array([gamma(red.w[i], red.weights) for i in range(T)]),
               milling=np.array([milling_index(red.y[i], red.w[i], red.weights) for i in range(T)]),
               y_final=red.y[-1], w_final=red.w[-1], simulate_time=red.simulate_time)
    out.update(_cert.certify_stage(cfg, sol, red, M, decision, w1=c.w1,
                                   term_quant=tb.term_quant, bound=tb.bound, diameter=diameter))
    if ref is not None:
        rred = reduce(ref, M=M)
        est = reference_estimate(sol, ref, rred, quantization=quantization)
        out["w1_reference"] = est.w1_reference
        out["w1_quantization"] = est.w1_quantization
    return KStage(**out, wall_time=time.perf_counter() - t0)


def _open_stages(cfg: Config, out_dir, resume: bool):
    """``(ResultFolder or None, StageStore, FolderLock or None)``: the result folder, its
    ``stages/`` store and the folder's lock (held by this process until the run ends)."""
    from .._lock import lock_folder
    from ..io import ResultFolder, StageStore

    if out_dir is None:
        return None, StageStore(None, cfg.digest()), None
    folder = ResultFolder(out_dir)
    lock = lock_folder(folder.path)
    try:
        stages = StageStore(folder / "stages", cfg.digest(), resume=resume,
                            describe={"config": cfg.to_json()})
        folder.clean_temporary()
    except BaseException:
        lock.release()
        raise
    return folder, stages, lock


def run(cfg: Config, *, out_dir=None, resume: bool = False, progress: bool | None = None,
        label: str | None = None, share_from=None, figures: bool = True) -> RunResult:
    """Run a scene (see the module docstring); with ``out_dir`` write the result folder.

    The run owns ``out_dir`` while it runs (its lock, ``kinred._lock``: another process is
    refused with :class:`~kinred.errors.FolderInUse`). ``label`` names the progress bar
    (default ``"kinred run <scene file>"``). ``share_from``: the result folder of another run
    of the same scene (``kinred certify`` passes the ``kinred run`` folder) whose stages are
    taken instead of computed where they are what this run would compute
    (:class:`SharedStages`); their status is ``"shared"``. ``figures=False``: the report is
    written without drawing its figures (each is a note saying so; about 2 s less per run, for
    sweeps that read ``summary.json`` and ``results.npz``).
    """
    if not isinstance(cfg, Config):
        raise InvalidInput(f"cfg must be a kinred.scenefile.Config, got {type(cfg).__name__}")
    if label is not None and not isinstance(label, str):
        raise InvalidInput(f"label must be a str or None, got {label!r}")
    if not isinstance(figures, bool):
        raise InvalidInput(f"figures must be True or False, got {figures!r}")
    shared = None if share_from is None else SharedStages(share_from, cfg)
    t_start = time.perf_counter()
    folder, stages, lock = _open_stages(cfg, out_dir, resume)
    try:
        return _run(cfg, folder, stages, shared, progress, label, t_start, figures)
    finally:
        stages.close()
        if lock is not None:
            lock.release()


def _run(cfg: Config, folder, stages, shared, progress, label, t_start,
         figures: bool) -> RunResult:
    names = ["solve"] + (["reference"] if cfg.reference_atoms else []) + [f"k{k}" for k in cfg.ks]
    if progress is None:
        progress = sys.stderr.isatty()
    from tqdm import tqdm

    bar = tqdm(total=len(names), desc=label or f"kinred run {Path(cfg.source).name}",
               unit="stage", disable=not progress, file=sys.stderr)
    bar.set_postfix_str("solve")
    a, sol = _solution(stages, shared, cfg, "solve", cfg.atoms, cfg.eps)
    bar.update(1)
    decision = _cert.decide(cfg, sol)
    if cfg.certify.enabled and not decision.on:
        warnings.warn(f"{cfg.source}: certify.enabled: {decision.note}; the run goes on without "
                      "certificates", KinredWarning, stacklevel=2)
    diameter, diameter_lower = _cert.phase_diameter(a["x"], a["v"])
    r = ref = None
    if cfg.reference_atoms:
        _check_reference(cfg, sol.n_atoms)
        bar.set_postfix_str("reference")
        r, ref = _solution(stages, shared, cfg, "reference", cfg.reference_atoms, None)
        bar.update(1)
    per_k = {}
    quant = None              # W1(μᴺ(t), μᴺ′(t)) on R^2d: the same for every k, computed once
    for k in cfg.ks:
        bar.set_postfix_str(f"k{k}")
        per_k[k] = KStage.from_arrays(_stage(
            stages, shared, f"k{k}",
            lambda k=k: _k_stage(cfg, k, sol, ref, decision, diameter, quant).arrays(),
            KStage.keys_for(reference=ref is not None)))
        quant = per_k[k].get("w1_quantization", quant)
        bar.update(1)
    bar.close()
    high = {"gamma": a["gamma"], "milling": a["milling"], "diameter": diameter,
            "diameter_lower": diameter_lower, "x_final": a["x"][-1], "v_final": a["v"][-1],
            "weights": a["weights"]}   # the last three for the report's positions figure
    if ref is not None:
        high["w1_quantization"] = per_k[cfg.ks[0]]["w1_quantization"]
        high["n_atoms_reference"] = int(r["n_atoms"])
        high["eps_reference"] = float(r["eps"])
    result = RunResult(config=cfg, t=sol.t, n_atoms=sol.n_atoms, eps=sol.eps, per_k=per_k,
                       high=high, stages=dict(stages.status),
                       wall_time=time.perf_counter() - t_start,
                       out_dir=None if folder is None else folder.path)
    if folder is not None:
        write_outputs(result, folder, figures=figures)
    return result


# ------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------
def _summary(result: RunResult) -> dict:
    cfg = result.config
    return {
        "study": "kinetic_run", "scene": cfg.source, "title": cfg.title, "smoke": cfg.smoke,
        "d": cfg.d, "n_atoms": result.n_atoms, "eps": result.eps, "ks": list(cfg.ks),
        "t_final": cfg.t_final, "wall_time_s": result.wall_time, "stages": result.stages,
        "digest": cfg.digest(),
        "per_k": {str(k): {"w1_final": float(r["w1"][-1]), "w1_max": float(np.max(r["w1"])),
                           "all_exact": bool(np.all(r["exact"])),
                           "w1_rel_gap_max": float(np.max(_rel_gap(r))),
                           "bound_final": float(r["bound"][-1]),
                           "term_jl_final": float(r["term_jl"][-1]),
                           "under_bound": bool(np.all(r["w1"] <= r["bound"] + 1e-12)),
                           "under_term_jl": bool(np.all(r["w1"] <= r["term_jl"] + 1e-12)),
                           **_cert.summary_numbers(result.t, r),
                           "gamma_final": float(r["gamma"][-1]),
                           "verdict": _verdict(r["gamma"][-1], cfg),
                           "milling_final": float(r["milling"][-1])}
                   for k, r in result.per_k.items()},
        "high": {"gamma_final": float(result.high["gamma"][-1]),
                 "verdict": _verdict(result.high["gamma"][-1], cfg),
                 "milling_final": float(result.high["milling"][-1]),
                 "diameter_final": float(result.high["diameter"][-1]),
                 "diameter_lower_final": float(result.high["diameter_lower"][-1])},
        "labels": _labels(result),
    }


def _labels(result: RunResult) -> dict:
    """``{name: label}`` of every per-k and ``high`` array of the run (:data:`LABELS`)."""
    names = set(result.high) | {n for r in result.per_k.values() for n in r}
    return {n: LABELS[n] for n in sorted(names) if n not in NOT_NUMBERS}


def write_outputs(result: RunResult, folder, *, figures: bool = True) -> Path:
    """``results.npz`` and ``summary.json`` first, then the PNG figures and ``report.html``.

    The numbers are on disk (and the folder complete) before anything is drawn; each figure is
    drawn in a guarded call, and one that fails is replaced by a note in the report; with
    ``figures=False`` none is drawn (each is such a note). Returns the path of
    ``summary.json``.
    """
    arrays = {"t": result.t, "gamma_high": result.high["gamma"],
              "milling_high": result.high["milling"], "diameter_high": result.high["diameter"],
              "diameter_lower_high": result.high["diameter_lower"]}
    skip = {"y_final", "w_final"}
    for k, r in result.per_k.items():
        for name, val in r.items():
            if name not in skip:
                arrays[f"k{k}_{name}"] = np.asarray(val)
    folder.write_npz("results.npz", arrays)
    summary = folder.mark_complete(_summary(result))
    drawn_figures = kinetic_report.figures(result, draw=figures)
    for drawn in drawn_figures:
        if drawn.png is not None:
            folder.write_bytes(drawn.name, drawn.png)
        else:           # a resumed run's earlier PNG would contradict the report's note
            (folder / drawn.name).unlink(missing_ok=True)
    folder.write_text("report.html", kinetic_report.report(result, drawn_figures).to_html())
    return summary
