"""Threaded chunks (core/parallel.py) change nothing but the time: the same bits with 1 or 2
threads, batch-independent link choices, and the vectorized link chaining against a plain
walk."""

import multiprocessing
import os
import threading
import time

import numpy as np
import pytest

from core import build_space, fit_surface
from core.configurations import _close_links, _unique_rows, constrained_delaunay
import core.parallel
from core.parallel import background, pmap, row_blocks, thread_count
from core.refine import make_space
from core.triangulation import FeatureLinkTriangulator, PlaneFitCost
from knotsets import knot_set


def test_thread_count_follows_the_environment(monkeypatch):
    monkeypatch.setenv("TCB_THREADS", "3")
    assert thread_count() == 3
    monkeypatch.setenv("TCB_THREADS", "0")
    assert thread_count() == 1
    monkeypatch.delenv("TCB_THREADS")
    default = thread_count()
    assert 1 <= default <= 4
    monkeypatch.setattr(core.parallel, "_warned", set())  # (whatever warned before)
    monkeypatch.setenv("TCB_THREADS", "many")
    with pytest.warns(RuntimeWarning, match="TCB_THREADS") as caught:
        assert thread_count() == default
        assert thread_count() == default  # (warned once: a fit asks often; user test)
    assert len([w for w in caught if "TCB_THREADS" in str(w.message)]) == 1


def _within(seconds, fn):
    """Run ``fn`` on a helper thread; fail (instead of hanging the suite) if it takes longer."""
    box = {}
    t = threading.Thread(target=lambda: box.update(value=fn()), daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), f"still running after {seconds} s (deadlock?)"
    return box["value"]


@pytest.mark.parametrize("threads", ["2", "3"])
def test_pmap_keeps_order_runs_nested_calls_serially_and_raises(monkeypatch, threads):
    monkeypatch.setenv("TCB_THREADS", threads)
    assert pmap(lambda i: i * i, range(10)) == [i * i for i in range(10)]
    # an inner pmap inside a chunk runs serially instead of waiting for the busy pool; also
    # from a thread that is not the main one (the Blender add-on fits on a worker thread)
    nested = _within(20, lambda: pmap(lambda i: sum(pmap(lambda j: j, range(i))), range(6)))
    assert nested == [0, 0, 1, 3, 6, 10]

    def boom(i):
        if i in (3, 5):
            raise KeyError(f"chunk {i}")
        return i

    with pytest.raises(KeyError, match="chunk 3"):
        pmap(boom, range(6))
    assert pmap(lambda i: i + 1, range(4)) == [1, 2, 3, 4]  # the pool survives


def test_changing_the_thread_count_does_not_cut_off_a_running_pmap(monkeypatch):
    monkeypatch.setenv("TCB_THREADS", "2")
    started = threading.Event()

    def slow(i):
        started.set()
        time.sleep(0.05)
        return i

    other = threading.Thread(target=lambda: box.update(v=pmap(slow, range(8))))
    box = {}
    other.start()
    started.wait(5)
    monkeypatch.setenv("TCB_THREADS", "3")  # a new pool for 3; the first keeps serving
    assert pmap(lambda i: -i, range(5)) == [0, -1, -2, -3, -4]
    other.join(20)
    assert box["v"] == list(range(8))


@pytest.mark.parametrize("threads", ["1", "2"])
def test_background_work_runs_ahead_on_its_own_thread_or_on_request(monkeypatch, threads):
    monkeypatch.setenv("TCB_THREADS", threads)
    ran_on, release = [], threading.Event()

    def work():
        ran_on.append(threading.current_thread())
        release.wait(5)
        return 42

    get = background(work)
    if threads == "1":  # nothing runs until asked for, then on the asking thread
        time.sleep(0.05)
        assert ran_on == []
        release.set()
        assert get() == 42 and ran_on == [threading.current_thread()]
    else:  # started at once on a thread that is neither this one nor a pmap worker
        deadline = time.perf_counter() + 5
        while not ran_on and time.perf_counter() < deadline:
            time.sleep(0.01)
        assert ran_on and ran_on[0].name == "tcb-background"
        assert pmap(lambda i: i, range(4)) == [0, 1, 2, 3]  # the pool is not held up by it
        release.set()
        assert _within(10, get) == 42
    assert get() == 42 and len(ran_on) == 1  # computed once

    def fails():
        raise ValueError("bad sample")

    failing = background(fails)
    for _ in range(2):
        with pytest.raises(ValueError, match="bad sample"):
            failing()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork is POSIX-only")
def test_a_forked_child_builds_its_own_pool(monkeypatch):
    monkeypatch.setenv("TCB_THREADS", "2")
    assert pmap(abs, [-1, -2]) == [1, 2]  # the parent's pool exists
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(1) as pool:
        result = pool.apply_async(pmap, (abs, [-3, -4, -5]))
        assert result.get(timeout=20) == [3, 4, 5]


@pytest.mark.parametrize("n", [0, 1, 4095, 4096, 10_000, 100_001])
def test_row_blocks_tile_the_range(monkeypatch, n):
    monkeypatch.setenv("TCB_THREADS", "2")
    blocks = row_blocks(n)
    covered = np.concatenate([np.arange(s, e) for s, e in blocks]) if blocks else np.zeros(0)
    assert np.array_equal(covered, np.arange(n))
    assert len(blocks) <= 4 and all(e - s >= min(n, 4096) for s, e in blocks)


def test_basis_matrix_is_bit_identical_with_one_and_two_threads(monkeypatch):
    space = build_space(knot_set("random", 150, 2, seed=3), 2)
    uv = np.random.default_rng(0).random((30_000, 2))
    mats = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("TCB_THREADS", threads)
        mats[threads] = space.evaluate_many(uv, [(0, 0), (1, 0), (0, 2)])
    for A, B in zip(mats["1"], mats["2"]):
        assert A.nnz > 0
        assert np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices)
        assert np.array_equal(A.data, B.data)


def test_fit_is_the_same_with_one_and_two_threads(monkeypatch):
    rng = np.random.default_rng(5)
    xy = rng.random((25_000, 2))
    pts = np.c_[xy, np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1]) + 0.2 * np.abs(xy[:, 1] - 0.5)]
    surfs = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("TCB_THREADS", threads)
        surfs[threads] = fit_surface(pts, max_iterations=2, max_control_points=800)
    assert np.array_equal(surfs["1"].control_points, surfs["2"].control_points)
    assert np.array_equal(surfs["1"].errors, surfs["2"].errors)


def test_link_choices_do_not_depend_on_the_batch(monkeypatch):
    """Feature-sensitive configurations are the same whether the links of a level are solved
    in one batch or in batches of 7 on two threads."""
    rng = np.random.default_rng(2)
    uv = rng.random((6000, 2))
    P = np.c_[uv, 0.25 * np.abs(uv[:, 1] - 0.3 - 0.4 * uv[:, 0])]
    K = knot_set("random", 60, 2, seed=2)
    n_inner = 60
    runs = []
    for batch, threads in ((10_000, "1"), (7, "2")):
        monkeypatch.setenv("TCB_THREADS", threads)
        monkeypatch.setattr(FeatureLinkTriangulator, "OPTIMAL_BATCH", batch)
        runs.append(make_space(K, 2, "tcb", PlaneFitCost(uv, P), n_inner).configurations)
    a, b = runs
    for level in range(3):
        assert np.array_equal(a.triangles[level], b.triangles[level])
        assert np.array_equal(a.interior[level], b.interior[level])


def test_unique_rows_matches_numpy_unique():
    rng = np.random.default_rng(0)
    for cols, high in ((1, 5), (2, 40), (3, 1000), (3, 3_000_000)):  # the last one: row sort
        rows = rng.integers(0, high, (500, cols))
        got, inv, cnt = _unique_rows(rows, return_counts=True)
        ref, rinv, rcnt = np.unique(rows, axis=0, return_inverse=True, return_counts=True)
        assert np.array_equal(got, ref) and np.array_equal(inv, rinv.reshape(-1))
        assert np.array_equal(cnt, rcnt)


def _walk_links(J, heads, tails):
    """Plain reference: per J, cancel opposite edges, then follow ``a -> b`` from the edge with
    the smallest (min, max) endpoints; a polygon only when one simple loop uses every edge."""
    out = {}
    for key in sorted({tuple(r) for r in J.tolist()}):
        net = {}
        for r, a, b in zip(J.tolist(), heads.tolist(), tails.tolist()):
            if tuple(r) == key:
                e = (min(a, b), max(a, b))
                net.setdefault(e, []).append(1 if a < b else -1)
        if any(abs(sum(s)) > 1 or len(s) > 2 for s in net.values()):
            out[key] = None
            continue
        edges = [(lo, hi) if sum(s) > 0 else (hi, lo) for (lo, hi), s in sorted(net.items()) if sum(s)]
        nxt = {}
        for a, b in edges:
            nxt.setdefault(a, []).append(b)
        if len(edges) < 3 or any(len(v) > 1 for v in nxt.values()):
            out[key] = None
            continue
        poly, v = [edges[0][0]], edges[0][1]
        while v != poly[0] and v in nxt and len(poly) <= len(edges):
            poly.append(v)
            v = nxt[v][0]
        out[key] = poly if v == poly[0] and len(poly) == len(edges) else None
    return out


def test_link_chaining_matches_a_plain_walk():
    rng = np.random.default_rng(4)
    cases = []
    for _ in range(300):  # random edge soups: pinched, open, doubled, several loops
        E = int(rng.integers(3, 30))
        h = rng.integers(0, 8, E)
        t = (h + rng.integers(1, 8, E)) % 8
        cases.append((rng.integers(0, 4, (E, 1)), h, t))
    for i in range(99):  # simple loops, and the same loop cut open or doubled
        m = int(rng.integers(3, 12))
        v = rng.permutation(20)[:m]
        h, t = v, np.roll(v, -1)
        kind = i % 3
        if kind == 1:
            h, t = h[1:], t[1:]
        elif kind == 2:
            h, t = np.r_[h, h[:2]], np.r_[t, t[:2]]
        cases.append((np.zeros((len(h), 1), dtype=np.int64), h, t))
    closed = 0
    for J, h, t in cases:
        groups, polys = _close_links(J, h, t)
        ref = _walk_links(J, h, t)
        assert [tuple(g) for g in groups.tolist()] == list(ref)
        assert polys == list(ref.values())
        closed += sum(p is not None for p in polys)
    assert closed >= 33  # the 33 simple loops were found, not only refused


def test_a_link_batch_without_data_inside_falls_back_like_a_mixed_batch(monkeypatch):
    """A non-convex pentagon whose only nearby point sits in its notch (inside the search
    ball, outside the polygon) gets the constrained Delaunay triangulation, alone in its batch
    or batched with a hexagon that has data."""
    rng = np.random.default_rng(0)
    ang = np.arange(6) * np.pi / 3
    hexagon = np.c_[np.cos(ang), np.sin(ang)]
    pentagon = np.array([[5, -1], [7, -1], [7, 1], [6, 0.2], [5, 1]], dtype=float)
    knots = np.vstack([hexagon, pentagon, [[0.05, 0.02], [5.6, -0.3]]])
    uv = np.vstack([rng.uniform(-0.6, 0.6, (60, 2)), [[6.0, 0.8]]])
    P = np.c_[uv, np.abs(uv[:, 0] - 0.1) + uv[:, 1] ** 2]
    polys = [tuple(range(6)), tuple(range(6, 11))]
    Js = [(11,), (12,)]
    results = []
    for batch in (1, 2):
        monkeypatch.setattr(FeatureLinkTriangulator, "OPTIMAL_BATCH", batch)
        tri = FeatureLinkTriangulator(PlaneFitCost(uv, P), 2)
        results.append(tri.triangulate_many(polys, knots, Js, level=1))
    assert results[0] == results[1]
    cdt = constrained_delaunay(polys[1], knots, Js[1], 1)
    assert sorted(map(sorted, results[0][1])) == sorted(map(sorted, cdt))
    assert len(results[0][0]) == 4
