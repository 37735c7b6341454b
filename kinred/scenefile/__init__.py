r"""Scene files: the schema of ``kinred run``'s input, registries, loader and :class:`Config`.

A scene file (TOML, ``docs/scene-file.md``, examples in ``examples/scenes/``) names the
effects, the initial phase-space measure, the quantization, the projections, the integrator
and the outputs of one ``kinred run``. Every table and key is described once, in
:data:`TABLES`, by a :class:`Key` (type, default, valid range or choices, one line of
documentation, the :class:`Config` attribute that holds it):

* :class:`Config` and :class:`CertifyOptions` are derived from :data:`TABLES`: adding a key is
  one :class:`Key` in its table (and, when it needs more than a range or choices, a check in
  the loader); keys added after the first format enter :meth:`Config.digest` only when they
  differ from their default, so result folders of older scenes still resume;
* :func:`config_from_dict` / :func:`load_config` validate with them: an unknown, missing,
  mistyped, non-finite or out-of-range key is a :class:`~kinred.errors.ConfigError` whose one
  line names the file, the table and key, the bad value and what is valid;
* the reference section of ``docs/scene-file.md`` is generated from them
  (:func:`reference_markdown`; ``python -m kinred.scenefile docs/scene-file.md`` rewrites it,
  and ``tests/test_scenefile.py`` fails when the page is out of date).

Two tables are open-ended and read registries: ``[[dynamics.effect]]`` (its ``type`` is a key
of :data:`EFFECTS`) and ``[dynamics.pairsum]`` (its ``method`` is a key of :data:`PAIRSUMS`,
which is :data:`kinred.pairsum.PAIRSUMS`, the registry ``Scene(pairsum="name")`` reads too).
Adding an effect type or a pair-sum backend is one call, e.g.::

    register_effect("quadratic", lambda p, d: Alignment(Quadratic(p["c"])),
                    keys=(Key("c", "number", REQUIRED, "coupling strength", low=0.0),),
                    doc="linear alignment, phi(s) = c")

after which scene files may use ``type = "quadratic"`` with the key ``c``, the loader checks
it, and the generated reference lists it. The integrator (``[integrate] method``) is read from
:data:`kinred.integrate.SOLVERS` (deterministic integrators).

The parts: the schema (:class:`Key`, in ``kinred._schema``), the tables
(``kinred/scenefile/_tables.py``), the effect registry (``_effects.py``), the configuration
(``_config.py``), the loader (``_loader.py``) and the reference generator (``_reference.py``).
"""

from .._schema import REQUIRED, Key
from ..pairsum import PAIRSUMS, PairSumType, register_pairsum, unregister_pairsum
from ._config import FIRST_FORMAT, CertifyOptions, Config
from ._effects import EFFECTS, EffectType, register_effect, unregister_effect
from ._loader import SMALL_SCENE, config_from_dict, load_config
from ._reference import BEGIN, END, reference_markdown
from ._tables import GROUPED, SMOKE_TARGETS, TABLES

__all__ = ["Key", "REQUIRED", "EffectType", "PairSumType", "EFFECTS", "PAIRSUMS", "TABLES",
           "register_effect", "unregister_effect", "register_pairsum", "unregister_pairsum",
           "CertifyOptions", "Config", "config_from_dict", "load_config", "reference_markdown",
           "SMALL_SCENE"]
