"""Sub-commands of the ``kinred`` CLI (see :mod:`kinred.cli` for the module protocol)."""
