"""Trajectories to the ecosystem: :meth:`Trajectory.to_xarray` (optional extra ``xarray``)."""

from __future__ import annotations

import numpy as np

from ..errors import MissingDependency

__all__ = ["to_xarray"]


def _import_xarray():
    try:
        import xarray
    except ImportError:
        raise MissingDependency(
            "Trajectory.to_xarray needs the optional package xarray, which is not installed: "
            "pip install 'kinred[xarray]' (or: pip install xarray)") from None
    return xarray


def _attr(value):
    """An attribute value NetCDF can store: numbers and strings as they are, else ``str``."""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, float, str, np.integer, np.floating)):
        return value
    return str(value)


def to_xarray(tr):
    """The trajectory ``tr`` as an ``xarray.Dataset`` (see :meth:`Trajectory.to_xarray`)."""
    from .._version import __version__

    xr = _import_xarray()
    data_vars, coords = {}, {"time": ("time", np.asarray(tr.t, dtype=float))}
    states = [(name, a) for name, a in (("x", tr.x), ("v", tr.v)) if a is not None]
    ts = np.asarray(tr.t_states if tr.t_states is not None else tr.t, dtype=float)
    st = "time" if np.array_equal(ts, coords["time"][1]) else "state_time"
    if states:
        _, n, d = states[0][1].shape
        coords["agent"] = ("agent", np.arange(n))
        coords["coordinate"] = ("coordinate", np.arange(d))
        if st != "time":                   # only the final state was kept
            coords[st] = (st, ts)
    for name, a in states:
        data_vars[name] = ((st, "agent", "coordinate"), np.asarray(a))
    if tr.weights is not None:
        data_vars["weights"] = (("agent",), np.asarray(tr.weights, dtype=float))
    for name, a in tr.observables.items():
        a = np.asarray(a)
        dims = ("time",) + tuple(f"{name}_dim{i}" for i in range(1, a.ndim))
        data_vars[name] = (dims, a)
    attrs = {"method": tr.method, "dt": float(tr.dt), "n_steps": int(tr.n_steps),
             "n_rejected": int(tr.n_rejected), "n_rhs_evals": int(tr.n_rhs_evals),
             "wall_time_s": float(tr.wall_time), "scene": tr.scene, "seed": _attr(tr.seed),
             "kinred_version": __version__}
    ds = xr.Dataset(data_vars, coords=coords, attrs=attrs)
    if "x" in ds:
        ds["x"].attrs["long_name"] = "positions"
    if "v" in ds:
        ds["v"].attrs["long_name"] = "velocities"
    if "weights" in ds:
        ds["weights"].attrs["long_name"] = "probability weights of the agents"
    return ds
