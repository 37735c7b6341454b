import os

os.environ.setdefault("MPLBACKEND", "Agg")

from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile(
    "kinred",
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=True,
)
settings.load_profile("kinred")

#: Modules whose module-scoped fixtures run for 15-35 s (a docs build, the quick Table 1 and
#: Figure 4 studies, the cost study): collected first, so that pytest-xdist starts them at
#: once and the other worker (and work stealing) fills around them, instead of one worker
#: meeting them at the end of its queue while the other idles.
SLOW_FIRST = ("tests/test_docs.py", "tests/test_table1.py", "tests/test_fig4.py",
              "tests/test_cost.py")


def pytest_collection_modifyitems(config, items):
    def rank(item):
        path = item.nodeid.split("::")[0]
        return SLOW_FIRST.index(path) if path in SLOW_FIRST else len(SLOW_FIRST)

    items.sort(key=rank)         # stable: the order inside each group is kept
