"""One module per study: a ``Config`` dataclass and ``run(config) -> result``.

* :mod:`kinred.experiments.table1` -- the paper's Table 1 and Figures 1-3 (§3.4.1).
"""
