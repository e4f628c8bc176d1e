"""The suite's order under ``make test`` (pytest-xdist, ``--dist worksteal``): the compile-heavy
directories (``conftest.COLD_COMPILE_FIRST``) lead the workers' first shares, as xdist deals them."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from conftest import COLD_COMPILE_FIRST, lead_shares, worksteal_shares

worksteal = pytest.importorskip("xdist.scheduler.worksteal")


class _Worker:
    """The part of a pytest-xdist worker controller that the scheduler calls."""

    def __init__(self, name: str):
        self.gateway = SimpleNamespace(id=name)
        self.shutting_down = False
        self.sent: list[int] = []

    def send_runtest_some(self, indices) -> None:
        self.sent += list(indices)

    def send_steal(self, indices) -> None:  # a share too short to run on asks for more: not here
        pass

    def shutdown(self) -> None:
        pass


def _first_shares(n_items: int, workers: int) -> list[list[int]]:
    """The indices xdist's work-stealing scheduler first sends each of ``workers`` workers."""
    config = SimpleNamespace(getvalue=lambda name: [f"{workers}*popen"])
    sched = worksteal.WorkStealingScheduling(config)
    nodes = [_Worker(f"gw{k}") for k in range(workers)]
    ids = [f"t{i}" for i in range(n_items)]
    for node in nodes:
        sched.add_node(node)
    for node in nodes:
        sched.add_node_collection(node, ids)
    sched.schedule()
    return [node.sent for node in nodes]


@pytest.mark.parametrize("n_items, workers", [(2212, 2), (2213, 2), (101, 3), (7, 4)])
def test_shares_are_those_xdist_deals(n_items, workers):
    shares = _first_shares(n_items, workers)
    assert [len(s) for s in shares] == worksteal_shares(n_items, workers)
    assert sum(shares, []) == list(range(n_items))  # contiguous, in order


def _items(names):
    return [SimpleNamespace(nodeid=n) for n in names]


def test_heavy_directories_lead_each_workers_share():
    design, integ = COLD_COMPILE_FIRST[:2]
    names = ([f"tests/analysis/test_a.py::t{i}" for i in range(6)] + [f"{design}test_g.py::t{i}" for i in range(3)]
             + [f"{integ}test_o.py::t{i}" for i in range(2)] + [f"tests/test_z.py::t{i}" for i in range(9)])
    out = [i.nodeid for i in lead_shares(_items(names), 2)]
    assert sorted(out) == sorted(names)
    first, second = out[:10], out[10:]
    assert first[:3] == [f"{design}test_g.py::t{i}" for i in range(3)]
    assert second[:2] == [f"{integ}test_o.py::t{i}" for i in range(2)]
    rest = [n for n in out if not n.startswith((design, integ))]
    assert rest == [n for n in names if not n.startswith((design, integ))]  # the others keep their order


def test_order_is_kept_when_a_share_cannot_hold_its_lead():
    design = COLD_COMPILE_FIRST[0]
    names = [f"{design}test_g.py::t{i}" for i in range(5)] + ["tests/test_z.py::t0"]
    assert [i.nodeid for i in lead_shares(_items(names), 2)] == names
