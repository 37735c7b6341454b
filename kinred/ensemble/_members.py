"""The members of an ensemble: the constants of a run, :class:`MemberFailed`, :func:`grid`,
member validation and :func:`config_hash` (what identifies a run's results)."""

from __future__ import annotations

import hashlib
import itertools
import json
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

from ..errors import InvalidInput, KinredError
from ..io import to_jsonable

#: Environment given to worker processes: one thread each.
THREAD_ENV: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}

#: Executors accepted by :func:`run_ensemble`.
EXECUTORS: tuple[str, ...] = ("serial", "processes", "dask")

_FORMAT = "kinred-ensemble/1"
_META = "__meta__"


class MemberFailed(KinredError, RuntimeError):
    """A member's function raised (or returned something invalid).

    Attributes
    ----------
    index : int
        The member's index in the member list.
    params : dict
        The member's parameters.
    remote_traceback : str
        The traceback text from the process that ran the member.
    """

    def __init__(self, message: str, *, index: int, params: dict, remote_traceback: str = ""):
        super().__init__(message)
        self.index = index
        self.params = params
        self.remote_traceback = remote_traceback

    def __reduce__(self):
        return (_rebuild_member_failed, (str(self), self.index, self.params, self.remote_traceback))


def _rebuild_member_failed(message, index, params, tb):
    return MemberFailed(message, index=index, params=params, remote_traceback=tb)


# ----------------------------------------------------------------------------------------------
# Members
# ----------------------------------------------------------------------------------------------
def _plain(value, name: str):
    """JSON-safe plain Python value (numpy scalars → Python; tuples → lists)."""
    try:
        out = to_jsonable(value)
    except InvalidInput as exc:
        raise InvalidInput(f"{name} must be JSON-serializable: {exc}") from None
    return out


def grid(**axes) -> list[dict]:
    """All combinations of the given parameter axes, as a list of member dicts.

    The order is the cartesian product in keyword order with the **last axis varying
    fastest** (``itertools.product``; nested loops written in keyword order), e.g.
    ``grid(k=[10, 5], realization=range(3))`` gives ``k=10`` with realizations 0, 1, 2, then
    ``k=5``. A string or any non-iterable value is a single-value axis. Values are converted
    to plain JSON types (numpy scalars to Python numbers).

    Parameters
    ----------
    **axes : iterable or scalar
        One axis per parameter name.

    Returns
    -------
    list of dict

    Examples
    --------
    >>> grid(beta=[1.5, 1.7], k=[10, 5], kind="gaussian")
    ... # doctest: +NORMALIZE_WHITESPACE
    [{'beta': 1.5, 'k': 10, 'kind': 'gaussian'}, {'beta': 1.5, 'k': 5, 'kind': 'gaussian'},
     {'beta': 1.7, 'k': 10, 'kind': 'gaussian'}, {'beta': 1.7, 'k': 5, 'kind': 'gaussian'}]
    """
    names = list(axes)
    values = []
    for name in names:
        v = axes[name]
        if isinstance(v, (str, bytes)) or not isinstance(v, Iterable) or isinstance(v, Mapping):
            v = [v]
        v = [_plain(x, f"grid axis {name!r}") for x in v]
        if not v:
            raise InvalidInput(f"grid axis {name!r} must hold at least one value, got an empty iterable")
        values.append(v)
    return [dict(zip(names, combo)) for combo in itertools.product(*values)]


def _check_members(members) -> list[dict]:
    if isinstance(members, (str, bytes, Mapping)) or not isinstance(members, Iterable):
        raise InvalidInput(f"members must be a list of dicts, got {type(members).__name__}")
    try:
        members = list(members)
    except TypeError:  # a 0-d array
        raise InvalidInput(f"members must be a list of dicts, got {members!r}") from None
    out = []
    for i, m in enumerate(members):
        if not isinstance(m, Mapping):
            raise InvalidInput(f"members[{i}] must be a dict of parameters, got {m!r}")
        out.append(_plain(dict(m), f"members[{i}]"))
    if not out:
        raise InvalidInput("members must hold at least one member, got an empty list")
    return out


def _fn_name(fn) -> str:
    return f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', repr(fn))}"


def _fn_identity(fn) -> str:
    """``module.qualname`` of a member function, as :func:`config_hash` hashes it.

    The module tells apart functions of one name (``table1.member`` and
    ``calibrate_table1.member`` are both ``member``). A function of the script being run
    (module ``__main__``) is named by the module it is when imported: ``python -m pkg.mod``
    gives ``pkg.mod``, ``python path/run.py`` gives ``run``, so a run started as a script
    resumes from ``import run``.
    """
    module = getattr(fn, "__module__", None) or "?"
    if module == "__main__":
        main = sys.modules.get("__main__")
        spec = getattr(main, "__spec__", None)
        if spec is not None and getattr(spec, "name", None):
            module = spec.name
        elif getattr(main, "__file__", None):
            module = Path(main.__file__).stem
    return f"{module}.{getattr(fn, '__qualname__', repr(fn))}"


def config_hash(master_seed: int, members: list[dict], fn_qualname: str, config=None) -> str:
    """SHA-256 of the canonical JSON of what determines a run's results.

    Hashed: the master seed, the member list, the function's name ``fn_qualname`` (as
    :func:`run_ensemble` calls it: ``_fn_identity``, ``module.qualname``, so a store does
    not resume with another module's function of the same name) and the optional user
    ``config``.

    Examples
    --------
    >>> config_hash(1, [{"k": 2}], "f") == config_hash(1, [{"k": 2}], "f")
    True
    >>> config_hash(1, [{"k": 2}], "f") == config_hash(2, [{"k": 2}], "f")
    False
    """
    payload = {
        "format": _FORMAT,
        "master_seed": int(master_seed),
        "members": members,
        "fn": fn_qualname,
        "config": _plain(config, "config"),
    }
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
