"""``Trajectory.to_xarray``: named dimensions, the run's values and metadata, missing xarray."""

import sys

import numpy as np
import pytest
import xarray as xr  # in the test extra: a missing xarray fails, never skips

import kinred
from kinred.dynamics import Aggregation, Alignment, CuckerSmale, Scene
from kinred.dynamics.kernels import Quadratic
from kinred.errors import KinredError, MissingDependency
from kinred.integrate import SaveAt, simulate


def _weighted_run():
    rng = np.random.default_rng(3)
    w = np.array([0.1, 0.2, 0.3, 0.4])
    scene = Scene([Alignment(CuckerSmale(G=0.8, beta=1.5))], normalize="sum", weights=w)
    x0, v0 = rng.standard_normal((4, 3)), rng.standard_normal((4, 3))
    return scene, simulate(scene, x0, v0, (0.0, 1.0), 0.125, save=SaveAt(every=2, states=True),
                           seed=11)


def test_dims_coords_values_and_attrs():
    scene, tr = _weighted_run()
    ds = tr.to_xarray()
    assert isinstance(ds, xr.Dataset)
    assert ds["x"].dims == ds["v"].dims == ("time", "agent", "coordinate")
    assert dict(ds.sizes) == {"time": 5, "agent": 4, "coordinate": 3}
    np.testing.assert_array_equal(ds["time"].values, [0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_array_equal(ds["agent"].values, np.arange(4))
    np.testing.assert_array_equal(ds["coordinate"].values, np.arange(3))
    # the values are the trajectory's, bit for bit
    assert np.array_equal(ds["x"].values, tr.x) and np.array_equal(ds["v"].values, tr.v)
    assert np.array_equal(ds["weights"].values, [0.1, 0.2, 0.3, 0.4])
    assert ds["weights"].dims == ("agent",)
    assert np.array_equal(ds["gamma"].values, tr.observables["gamma"])
    # selection by name and time: the state at t = 0.5 of agent 2
    assert np.array_equal(ds["v"].sel(time=0.5, agent=2).values, tr.v[2, 2])
    a = ds.attrs
    assert a["method"] == "euler" and a["dt"] == 0.125 and a["n_steps"] == 8
    assert a["seed"] == 11 and a["kinred_version"] == kinred.__version__
    assert a["scene"].startswith("Scene([Alignment(kernel=CuckerSmale(G=0.8, beta=1.5)")
    assert "normalize='sum'" in a["scene"] and "weighted agents" in a["scene"]
    # every attribute is a type NetCDF can store
    assert all(isinstance(v, (int, float, str)) for v in a.values())


def test_first_order_scene_and_unweighted():
    x0 = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    tr = simulate(Scene([Aggregation(Quadratic(1.0))]), x0, None, (0.0, 0.5), 0.1,
                  save=SaveAt(states=True))
    ds = tr.to_xarray()
    assert "x" in ds and "v" not in ds and "weights" not in ds
    assert ds["x"].dims == ("time", "agent", "coordinate")
    assert np.array_equal(ds["x"].values, tr.x)
    # the centroid is conserved by aggregation: x̄(t) = (1/3, 2/3) at every saved time
    np.testing.assert_allclose(ds["x"].mean("agent").values, np.tile([1 / 3, 2 / 3], (6, 1)),
                               rtol=0, atol=1e-14)
    assert ds.attrs["seed"] == "None" and "weighted" not in ds.attrs["scene"]


def test_default_run_exports_its_observables_and_final_state():
    rng = np.random.default_rng(0)
    tr = simulate(Scene([Alignment()]), rng.random((5, 2)), rng.random((5, 2)), (0.0, 1.0), 0.5)
    ds = tr.to_xarray()
    assert set(ds.data_vars) == set(tr.observables) | {"x", "v"}
    assert ds["gamma"].dims == ("time",) and ds["x"].dims == ("state_time", "agent", "coordinate")
    assert ds["state_time"].values.tolist() == [1.0] and ds.sizes["time"] == 3
    assert np.array_equal(ds["v"].values, tr.v) and np.array_equal(ds["x"].values[0], tr.x[-1])


def test_missing_xarray_is_a_clear_kinred_error(monkeypatch):
    _, tr = _weighted_run()
    monkeypatch.setitem(sys.modules, "xarray", None)      # `import xarray` raises ImportError
    with pytest.raises(MissingDependency, match=r"pip install 'kinred\[xarray\]'") as info:
        tr.to_xarray()
    assert isinstance(info.value, KinredError) and isinstance(info.value, ImportError)
    assert "xarray" in str(info.value) and "not installed" in str(info.value)
