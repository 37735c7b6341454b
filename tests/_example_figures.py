"""A matplotlib backend for the example smoke runs of tests/test_examples.py: Agg, and at
the end of the script every figure still open is saved as ``figure_NNN.png`` in the working
directory (what the documentation's gallery renders under the script's code).

Used as ``MPLBACKEND=module://_example_figures`` with this folder on ``PYTHONPATH``; imported
any other way (pytest's doctest collection) it does nothing.
"""

import atexit
import os

from matplotlib.backends.backend_agg import FigureCanvas, FigureManager  # noqa: F401

BACKEND = "module://_example_figures"


def save_open_figures(folder: str = ".") -> list:
    """Save every open pyplot figure as ``folder/figure_NNN.png``; return the paths."""
    import matplotlib.pyplot as plt

    paths = []
    for i, num in enumerate(plt.get_fignums(), 1):
        paths.append(os.path.join(folder, f"figure_{i:03d}.png"))
        plt.figure(num).savefig(paths[-1])
    return paths


if os.environ.get("MPLBACKEND") == BACKEND:
    atexit.register(save_open_figures)
