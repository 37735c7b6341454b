"""One module per study: a ``Config`` dataclass and ``run(config) -> result``.

* :mod:`kinred.experiments.table1` -- the paper's Table 1 and Figures 1-3 (§3.4.1).
* :mod:`kinred.experiments.calibrate_table1` -- which coupling G matches the most of Table 1's
  cells (``kinred paper calibrate``).
* :mod:`kinred.experiments.fig4` -- the paper's Figure 4 (§3.4.2) and the three recovery
  strategies of §3.3.1.
* :mod:`kinred.experiments.kinetic_run` -- ``kinred run scene.toml`` (§4).
* :mod:`kinred.experiments.demo` -- the main job, ``kinred demo``.
* :mod:`kinred.experiments.cost` -- what accuracy costs in time, ``kinred cost``.
"""
