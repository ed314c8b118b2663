"""Reconstruction end to end (method.md sections 4-7): accuracy on known data, creases, disk
meshes, local control, files, cancellation and bad input."""

import io
import json
import re
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from core import (
    CancelledError,
    FileFormatError,
    InvalidInputError,
    ParameterizationError,
    TCBError,
    TCBSurface,
    TopologyError,
    build_space,
    fit_surface,
)
from core.errors import OutlierError
from core.fit import fit_control_points
from core.geometry import point_mesh_distance, quad_triangles
from core import refine
import core.surface
from core.surface import FORMAT_VERSION
from core.surface import data_swings
from core.refine import UNEVEN_DENSITY, area_weights, automatic_start, next_start
from core.meshio import read_geometry
from core.simplex import orient2d
from knotsets import knot_set
from meshes import bent_sheet, noisy_grid, noisy_sphere_cap

DATA = __import__("pathlib").Path(__file__).resolve().parents[2] / "data"


def franke(x, y):
    return (
        0.75 * np.exp(-((9 * x - 2) ** 2 + (9 * y - 2) ** 2) / 4)
        + 0.75 * np.exp(-((9 * x + 1) ** 2) / 49 - (9 * y + 1) / 10)
        + 0.5 * np.exp(-((9 * x - 7) ** 2 + (9 * y - 3) ** 2) / 4)
        - 0.2 * np.exp(-((9 * x - 4) ** 2) - (9 * y - 7) ** 2)
    )


def ridge_cloud(n=6000, seed=0):
    xy = np.random.default_rng(seed).random((n, 2))
    return np.c_[xy, 0.25 * np.abs(xy[:, 1] - 0.5 - 0.15 * np.sin(4 * xy[:, 0]))]


@pytest.fixture(scope="module")
def nefertiti():
    points, faces = read_geometry(DATA / "nefertiti.off")
    return points, faces, fit_surface(points, faces, tolerance=1e-3)


@pytest.mark.parametrize("degree", [2, 3])
def test_polynomial_surface_in_the_parameters_is_reproduced(degree):
    knots = knot_set("random", 50, degree, seed=1, rings=degree)
    space = build_space(knots, degree)
    uv = np.random.default_rng(2).random((20000, 2))
    u, v = uv.T
    z = 0.3 * u**2 - 0.5 * u * v + 0.2 * v - 0.1 + (0.4 * v**3 if degree == 3 else 0.0)
    points = np.c_[u + 0.1 * v**2, v - 0.2 * u * v, z]
    # without fairing (which would pull towards planes): pure least squares where there is
    # data, fairing only for the control points no data determines
    fit = fit_control_points(space, uv, points, smoothness=0.0)
    # The cubic TCB basis here is linearly dependent (rank 287 of 292 on the data, condition
    # 1.5e17 measured with an SVD): the solver's small ridge + iterated Tikhonov still
    # reproduces the cubic (measured 1e-13; a fixed 1e-12 ridge with 4 steps reached 1.5e-7)
    assert fit.max < 1e-8
    assert np.all(np.isfinite(fit.control_points))
    assert np.abs(fit.control_points).max() < 10  # the data-free ones stay near the surface


@pytest.mark.parametrize("smoothness", [1e-4, 1e-2])
def test_a_plane_is_reproduced_with_fairing_and_keeps_its_edges(smoothness):
    """The fairing pulls towards the data's affine fit, not towards a constant: a scattered
    tilted plane (100 x 100 units) comes out exact at any smoothness, its tessellation reaches
    the data's edges, and a cloud's in-plane coordinates are not bent (before: in-plane errors
    of 0.07 and edges drawn in by 0.01 at the default smoothness)."""
    xy = np.random.default_rng(8).random((3000, 2)) * 100.0
    points = np.c_[xy, 0.3 * xy[:, 0] - 0.1 * xy[:, 1] + 7.0]
    surf = fit_surface(points, smoothness=smoothness)
    assert surf.report["max"] < 1e-9 * surf.report["diagonal"]
    verts, _ = surf.tessellate(32)
    lo, hi = points.min(axis=0), points.max(axis=0)
    np.testing.assert_allclose(verts.min(axis=0), lo, rtol=0, atol=1e-9 * 100)
    np.testing.assert_allclose(verts.max(axis=0), hi, rtol=0, atol=1e-9 * 100)


def test_franke_20000_points_quadratic_within_600_control_points():
    xy = np.random.default_rng(0).random((20000, 2))
    z = franke(*xy.T)
    surf = fit_surface(np.c_[xy, z], degree=2, max_control_points=600, tolerance=1e-4)
    assert surf.report["control_points"] <= 600
    assert surf.report["rms"] <= 1e-3 * np.ptp(z)
    assert np.all(np.isfinite(surf.control_points))


def test_the_net_follows_the_tolerance_and_the_start_without_one_is_unchanged():
    """With a tolerance the loop sizes its start (core.refine.next_start): a probe with a
    quarter of the automatic start's knots, then the count its error predicts. A loose
    tolerance gives a smaller net than a tight one, both met, and the tight one a smaller net
    than the fixed start (benchmarks/net_size.py: 143 / 301 / 467 control points on 20 000
    points). Without a tolerance the start is the automatic one, as before."""
    xy = np.random.default_rng(0).random((8000, 2))
    P = np.c_[xy, franke(*xy.T)]
    start = automatic_start("tcb", 2000)
    fixed = fit_surface(P, tolerance=1e-3, initial_knots=start)
    assert fixed.report["history"][0]["interior_knots"] == start
    cps = {}
    for tol in (1e-2, 1e-3):
        r = fit_surface(P, tolerance=tol).report
        assert r["stop_reason"] == "tolerance reached" and r["rms_rel"] <= tol
        assert r["history"][0]["interior_knots"] == start // 4  # the probe
        assert r["history"][0]["knots_placed"] == "afresh"
        cps[tol] = r["control_points"]
    assert cps[1e-2] < cps[1e-3] < fixed.report["control_points"]
    free = fit_surface(P, tolerance=0, max_iterations=2)
    same = fit_surface(P, tolerance=0, max_iterations=2, initial_knots=start)
    np.testing.assert_array_equal(free.control_points, same.control_points)
    assert [h["knots_placed"] for h in free.report["history"]] == ["afresh", "inserted"]


def test_a_budget_the_fit_does_not_reach_does_not_change_it():
    """The sizing's probe and largest start are those of the default budget
    (core.refine.PROBE_BUDGET) for any larger budget given: sized from the budget, budgets of
    2000 and 5000 gave three_peaks.off at 1e-3 nets of 647 and 1313 control points (user test
    F7; benchmarks/budgets.py). Here Franke at 2e-3: the same net, bit for bit, at 2000, 5000
    and 20 000; a smaller budget sizes from its own start, as before. One iteration (no
    sizing) fits that start too: budget 5000 had 400 interior knots, 2000 166."""
    xy = np.random.default_rng(3).random((8000, 2))
    P = np.c_[xy, franke(*xy.T)]
    runs = {b: fit_surface(P, tolerance=2e-3, max_control_points=b)
            for b in (2000, 5000, 20_000)}
    start = automatic_start("tcb", refine.PROBE_BUDGET)
    for b, surf in runs.items():
        r = surf.report
        assert r["stop_reason"] == "tolerance reached" and r["rms_rel"] <= 2e-3, b
        assert r["history"][0]["interior_knots"] == start // refine.PROBE_FRACTION, b
        np.testing.assert_array_equal(surf.control_points, runs[2000].control_points)
    assert runs[2000].report["control_points"] < 1000
    small = fit_surface(P, tolerance=2e-3, max_control_points=1000).report
    assert small["history"][0]["interior_knots"] == automatic_start("tcb", 1000) // 4
    assert small["control_points"] <= 1000 and small["rms_rel"] <= 2e-3
    # one iteration (no sizing): the default budget's start too, or the budget's own if smaller
    once = {b: fit_surface(P, tolerance=2e-3, max_control_points=b, max_iterations=1).report
            for b in (300, 2000, 5000)}
    assert [once[b]["history"][0]["interior_knots"] for b in once] == [
        automatic_start("tcb", 300), start, start]
    # ... but a start the insertions could not grow to the prediction by the iteration limit
    # jumps past it, up to the budget's own (review: 5000 at 5 iterations had stopped at 673
    # control points, its own start reaching 1654)
    far = fit_surface(P, tolerance=1e-6, max_control_points=5000, max_iterations=5).report
    assert far["history"][1]["interior_knots"] == automatic_start("tcb", 5000) > start
    assert far["control_points"] > 2 * fit_surface(P, tolerance=1e-6, max_control_points=2000,
                                                   max_iterations=5).report["control_points"]


def test_a_loose_tolerance_on_a_smooth_shape_gets_a_small_net(monkeypatch):
    """A fresh start that meets the tolerance with room to spare is followed by coarser fresh
    starts sized for half the tolerance (core.refine.SHRINK_TARGET; at most SHRINK_FRACTION of
    the knots, at least MIN_START_KNOTS) while they meet it, with their max error within
    SHRINK_MAX times the tolerance or the finer fit's max: a plane got 148 control points, the
    probe's, whatever the tolerance; now 40, and a bump at 1e-2 / 3e-3 37 / 52 (140 before).
    Where half the tolerance needs about the probe's knots it stays (the bump at 3e-4). The
    first coarser start that misses ends the run, and the last that met it is returned, unless
    one start halfway between them (geometric mean of the knots, SHRINK_SPLIT) meets it: the
    bump at 7e-4 (82 control points missed the max by 3%, 105 met it; 140 before); the bump
    at 3e-3 held to its max (SHRINK_MAX 1: its 52 control points have a max of 1.1x the
    tolerance), one made to miss the RMS (aimed at 4x the tolerance), and one that swings (it
    had been taken back as a sizing restart to the finer start, which shrank to it again,
    until the iteration limit: review). ``initial_knots`` given is kept."""
    xy = np.random.default_rng(0).random((3000, 2))
    probe = automatic_start("tcb", 2000) // 4

    def run(z, tol, **kw):
        r = fit_surface(np.c_[xy, z], tolerance=tol, **kw).report
        h = r["history"]
        knots = [x["interior_knots"] for x in h]
        assert r["stop_reason"] == "tolerance reached" and r["rms_rel"] <= tol
        split = len(h) > 2 and knots[-1] > knots[-2]  # the start halfway ...
        chain = h[:-1] if split else h
        assert knots[0] == probe and all(a > b for a, b in zip(knots[:len(chain)],
                                                                 knots[1:len(chain)]))
        assert all(x["knots_placed"] == "afresh" for x in h)
        limit = refine.SHRINK_MAX * tol

        def met(x, finer):
            return x["rms_rel"] <= tol and "swings" not in x and x["max_rel"] <= max(
                limit, finer["max_rel"])
        assert all(x["rms_rel"] <= tol for x in chain[:-1])  # only the last can miss ...
        for finer, coarser in zip(chain[:-2], chain[1:-1]):
            assert met(coarser, finer)
        missed = len(chain) > 1 and not met(chain[-1], chain[-2])
        if split:  # ... after a miss, between it and the fit before
            assert missed and knots[-1] == round(np.sqrt(knots[-3] * knots[-2]))
            kept = h[-1] if met(h[-1], h[-3]) else h[-3]
        else:
            kept = h[-2] if missed else h[-1]  # ... and then the one before it is returned
        assert r["returned_iteration"] == kept["iteration"]
        assert r["control_points"] == kept["control_points"]
        return r, knots

    plane = 0.3 * xy[:, 0] + 0.1 * xy[:, 1]
    r, knots = run(plane, 1e-2)
    assert knots == [probe, 6] and r["control_points"] <= 45 and r["rms_rel"] < 1e-12
    assert fit_surface(np.c_[xy, plane], tolerance=1e-2,
                       initial_knots=probe).report["control_points"] > 100
    bump = 0.2 * np.exp(-4 * ((xy - 0.5) ** 2).sum(axis=1))
    loose, knots = run(bump, 1e-2)
    assert len(knots) >= 2 and loose["control_points"] <= 45
    r, knots = run(bump, 3e-3)  # (its max 1.1x the tolerance: within SHRINK_MAX)
    assert len(knots) == 2 and r["control_points"] < 60 and 3e-3 < r["max_rel"]
    assert len(run(bump, 3e-4)[1]) == 1
    r, knots = run(bump, 7e-4)  # a miss, then the start halfway, which meets it
    h = r["history"]
    assert len(knots) == 3 and h[1]["max_rel"] > 1.4e-3 and r["returned_iteration"] == 3
    assert r["control_points"] < 0.8 * h[0]["control_points"]
    monkeypatch.setattr(refine, "SHRINK_SPLIT", np.inf)  # (no start halfway)
    monkeypatch.setattr(refine, "SHRINK_MAX", 1.0)  # every point within the tolerance
    r, knots = run(bump, 3e-3)  # the coarser start meets the RMS, not the max
    h = r["history"]
    assert len(knots) == 2 and h[1]["rms_rel"] <= 3e-3 < h[1]["max_rel"]
    assert h[1]["control_points"] < 0.6 * r["control_points"] == 0.6 * h[0]["control_points"]
    monkeypatch.setattr(refine, "SHRINK_MAX", 2.0)
    monkeypatch.setattr(refine, "SHRINK_TARGET", 4.0)
    r, knots = run(bump, 1e-3)
    assert len(knots) == 2 and r["history"][-1]["rms_rel"] > 1e-3  # the miss
    monkeypatch.setattr(refine, "SHRINK_TARGET", 0.5)
    swing_places = refine.swing_places

    def swinging(space, C, uv, points, errors, *args, domain=False, **kw):  # coarse ones swing
        where, checked, largest = swing_places(space, C, uv, points, errors, *args,
                                               domain=domain, **kw)
        if not domain and space.n_basis <= 120:
            where = np.vstack([where, [[0.5, 0.5]]])
        return where, checked, largest

    monkeypatch.setattr(refine, "swing_places", swinging)
    r, knots = run(bump, 1e-2, max_iterations=8)
    assert len(knots) == 2 and r["history"][-1]["swings"] == 1


def test_refine_below_the_surface_budget_is_refused_and_a_far_tolerance_grows_fast():
    """refine() with a budget below the surface's control points raises a specific error (it
    was a bare AssertionError); towards a tolerance 100x tighter the net doubles per iteration
    (the error-rate model, capped at doubling) instead of growing by 10 knots."""
    xy = np.random.default_rng(0).random((5000, 2))
    P = np.c_[xy, franke(*xy.T)]
    coarse = fit_surface(P, tolerance=1e-2)
    n = coarse.report["control_points"]
    with pytest.raises(InvalidInputError, match=f"already has {n} control points"):
        coarse.refine(P, max_control_points=n - 1)
    # at another degree the same knots make another count: the message names the degrees
    with pytest.raises(InvalidInputError, match=r"has, at degree 3 \(it was fitted at degree 2\), "
                       r"\d+ control points, more than the maximum of " + str(n)):
        coarse.refine(P, degree=3, max_control_points=n)
    fine = coarse.refine(P, tolerance=1e-4, max_iterations=3)
    h = fine.report["history"][len(coarse.report["history"]):]
    assert [x["knots_placed"] for x in h] == ["continued", "inserted", "inserted"]
    knots = [x["interior_knots"] for x in h]
    assert knots[0] == coarse.report["history"][-1]["interior_knots"]
    assert knots[1] >= 1.8 * knots[0] and knots[2] >= 1.8 * knots[1]
    assert fine.report["rms_rel"] < 0.2 * coarse.report["rms_rel"]


def test_sized_restarts_place_knots_on_all_points_and_the_max_criterion_keeps_the_fit_that_met_it(
        monkeypatch):
    """Above ITERATION_POINTS the restart at the automatic start is the fixed start's first
    fit (its knots are placed on all points, not on the iterations' subset); with the
    criterion "max" the surface returned meets the tolerance the loop reached (here the last
    fit is also the one of lowest RMS: a case where they differ was not constructed)."""
    import core.refine as refine

    monkeypatch.setattr(refine, "ITERATION_POINTS", 2000)
    xy = np.random.default_rng(2).random((6000, 2))
    P = np.c_[xy, franke(*xy.T)]
    start = automatic_start("tcb", 2000)
    sized = fit_surface(P, tolerance=1e-5, max_iterations=2).report["history"]
    fixed = fit_surface(P, tolerance=1e-5, max_iterations=1, initial_knots=start).report["history"]
    assert [h["interior_knots"] for h in sized] == [start // 4, start]
    assert sized[1]["rms"] == pytest.approx(fixed[0]["rms"], rel=1e-12)
    for tol in (3e-2, 1e-2, 3e-3):  # probe only; probe and a restart; probe and the start
        r = fit_surface(P[:3000], criterion="max", tolerance=tol).report
        assert r["stop_reason"] == "tolerance reached" and r["max_rel"] <= tol


def test_the_max_criterion_returns_the_fit_of_lowest_max_when_it_misses_the_tolerance():
    """With the criterion "max" and a tolerance out of reach, the surface returned is the fit
    of lowest max error, not of lowest RMS: Renka's cosine peak (F10) on 3000 points, five
    fits, the fifth of lower RMS (3.41e-3 against 3.68e-3) but larger max (2.9e-2 against
    2.1e-2). A grid mesh run out of budget had returned 1917 control points with a max of
    1.42e-4 where 812 had reached 1.06e-4 (user test)."""
    xy = np.random.default_rng(0).random((3000, 2))
    r = np.sqrt((80.0 * xy[:, 0] - 40.0) ** 2 + (90.0 * xy[:, 1] - 45.0) ** 2)
    P = np.c_[xy, np.exp(-0.04 * r) * np.cos(0.15 * r)]
    for criterion, key in (("max", "max_rel"), ("rms", "rms_rel")):
        rep = fit_surface(P, tolerance=1e-6, criterion=criterion, max_iterations=5,
                          max_control_points=600).report
        h = rep["history"]
        assert len(h) == 5 and all(x["control_points"] <= 600 for x in h)
        best = min(h, key=lambda x: x[key])
        # (the returned fit's errors are measured again: the same to rounding)
        assert rep["returned_iteration"] == best["iteration"]
        assert rep[key] == pytest.approx(best[key], rel=1e-12)
        if criterion == "max":
            assert best is not h[-1] and h[-1]["rms_rel"] < best["rms_rel"]
            # the command line says why (it said "of lowest RMS": review)
            from core.cli import _returned

            assert _returned(rep, "max") == (f"; the surface is iteration {best['iteration']}'s "
                                             "(lowest max error)")


def test_a_tolerance_below_the_noise_stops_when_the_error_stops_falling():
    """Gaussian noise of 0.01 on a smooth height field and a tolerance far below it: the RMS
    stays at the noise level however many knots are inserted, so the loop stops with "the
    error stopped falling" instead of spending the budget on fitting the noise (it used 1988
    control points, 14 fits, and moved farther from the true shape). Clean data with the same
    tolerance refine on."""
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (10000, 2))
    shape = lambda x, y: 0.3 * np.exp(-4 * (x * x + y * y)) + 0.1 * np.sin(3 * x) * np.cos(2 * y)  # noqa: E731
    noisy = np.c_[xy, shape(*xy.T) + 0.01 * rng.standard_normal(len(xy))]
    r = fit_surface(noisy, tolerance=1e-4).report
    assert r["stop_reason"] == "the error stopped falling"
    assert r["control_points"] < 1000 and len(r["history"]) <= 6
    assert 0.008 < r["rms"] < 0.0105  # the noise level
    # ... which the points' scatter across a smooth surface measures (local_noise)
    assert 0.8 * r["rms"] < r["noise"] < 1.05 * r["rms"] and core.surface.stopped_at_noise(r)
    clean = fit_surface(np.c_[xy, shape(*xy.T)], tolerance=1e-5, max_control_points=600).report
    assert clean["stop_reason"] == "control-point budget reached"
    # a clean CAD mesh whose RMS is not monotone from fit to fit (4.93, 4.98, 4.63, 4.80 e-4):
    # comparing single fits over 3 insertions stopped it one fit short of the tolerance
    pts, faces = read_geometry(DATA / "patch-01.off")
    r = fit_surface(pts, faces, tolerance=4.5e-4, max_control_points=5000).report
    assert r["stop_reason"] == "tolerance reached"


def off_wavy(surf, faces) -> float:
    """RMS distance (over the bounding box's diagonal) of ``surf`` from the noise-free height
    field of tests/meshes.py's noisy_grid, at 20 000 random points of the mesh's faces in the
    parameters, 0.02 inside the unit square (height differences times the cosine of the slope)."""
    from meshes import wavy

    uv = np.asarray(surf.parameterization.uv)
    rng = np.random.default_rng(5)
    corners = uv[faces[rng.integers(len(faces), size=20_000)]]
    x, y, z = surf((corners * rng.dirichlet([1, 1, 1], 20_000)[:, :, None]).sum(axis=1)).T
    gx = 0.8 * np.cos(4 * x) * np.cos(3 * y) + 0.1 * y  # the height field's gradient
    gy = -0.6 * np.sin(4 * x) * np.sin(3 * y) + 0.1 * x
    off = (z - wavy(x, y)) / np.sqrt(1 + gx * gx + gy * gy)
    inside = (np.minimum(x, y) > 0.02) & (np.maximum(x, y) < 0.98)
    return float(np.sqrt(np.mean(off[inside] ** 2)) / surf.report["diagonal"])


def stalled_without_warnings(points, faces):
    """``fit_surface`` of a noisy mesh at the default tolerance, which must stop because the
    error stopped falling, with under 300 control points and no warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        surf = fit_surface(points, faces)
    assert surf.report["stop_reason"] == refine.STALLED, surf.report["stop_reason"]
    assert surf.report["control_points"] < 300
    return surf


def test_a_noisy_mesh_counts_its_vertices_and_stops_when_its_error_stops_falling(monkeypatch):
    """A grid mesh of 41 x 41 vertices with noise of 0.2% of its diagonal, at the default
    tolerance (0.1%, below the noise). A mesh is fitted to its vertices and to points sampled
    on its faces, 20 per vertex: counted against them, the net's estimated error at new
    points did not rise, and the run took 1573 control points, more than the mesh has
    vertices, 1.31e-3 of the diagonal off the noise-free surface. Its noise measured
    (``report["noise"]``, core.parameterize.local_noise) is above 0.3 times the tolerance, so
    the vertices alone count: the error stops falling at about 150 control points, 5.7e-4 off.
    A clean mesh measures no noise and counts the samples (a fit that counted its vertices
    stopped a half cylinder at 1e-4 early, as if stalled)."""

    noisy, faces = noisy_grid(41, 0.002)
    surf = stalled_without_warnings(noisy, faces)
    r = surf.report
    assert 0.85 * 0.002 < r["noise_rel"] < 1.05 * 0.002
    assert r["noise"] == pytest.approx(r["noise_rel"] * r["diagonal"], rel=1e-12)
    off = off_wavy(surf, faces)
    assert off < 8e-4
    monkeypatch.setattr(core.surface, "NOISE_COUNTS", np.inf)  # the samples counted
    chased = fit_surface(noisy, faces)
    assert chased.report["control_points"] > 1000 and off_wavy(chased, faces) > 1.5 * off
    monkeypatch.undo()
    clean, _ = noisy_grid(41, 0.0)
    r = fit_surface(clean, faces).report
    assert r["noise"] == 0.0 and r["stop_reason"] == "tolerance reached"


def test_a_finely_meshed_noisy_scan_stops_on_its_errors_across_the_surface():
    """A grid mesh of 81 x 81 vertices with noise of 0.5% of its diagonal (0.6 times its
    spacing): its map does not follow the noise along the surface, which stays in the errors
    at the vertices (RMS 1.7 times the noise) and fell slowly as the net grew, so the run went
    on to 734 control points, 1.6e-3 of the diagonal off the noise-free surface. The stall test
    now takes the errors along the vertices' normals (``FitResult.across``): about 140 control
    points, 8.9e-4 off; the summary calls it noise (core.surface.stopped_at_noise). The fold
    check weighs the surface against the same normals, not the noisy faces': no fold (the
    faces' normals had it folded on 0.96%, the noise-free surface's none)."""

    noisy, faces = noisy_grid(81, 0.005)
    surf = stalled_without_warnings(noisy, faces)
    r = surf.report
    assert r["rms"] > 1.5 * r["noise"] and core.surface.stopped_at_noise(r)
    assert off_wavy(surf, faces) < 1.2e-3
    assert r["folded"] == 0.0


def test_the_noise_is_near_a_missed_tolerance_only_when_the_fit_has_not_gone_far_below_it():
    """``noise_near_tolerance``: the noise at least half an RMS tolerance (a sixth of a max
    one, whose noise reaches about 3 times as far) and between 0.4 times the RMS reached and
    2.5 times it (noise in three directions leaves up to sqrt(3) times itself at a mesh's
    vertices; a fit whose RMS fell somewhat below the noise has begun to follow it: a noisy
    cap that Refine took to its budget was told to raise it, user test). A coarse mesh whose
    curvature scores as noise far above the RMS a fit reached (the scanned face: 3.5e-3 of the
    diagonal, fitted to 4.3e-4) is not held off by noise, nor is
    a fit whose RMS is mostly not noise (a clean 16 x 16 grid of a quadric: 3.9e-5 against
    2.1e-4 at a tolerance of 1e-9). Tolerances as given: relative to the diagonal, or
    absolute."""
    near = core.surface.noise_near_tolerance
    report = {"noise": 0.02, "rms": 0.03, "diagonal": 10.0}
    assert near(report, 4e-3, True, "rms") and not near(report, 5e-3, True, "rms")
    assert near(report, 0.04, False, "rms") and not near(report, 0.05, False, "rms")
    assert near(report, 0.1, False, "max") and not near(report, 0.15, False, "max")
    assert near({**report, "rms": 0.0081}, 4e-3, True, "rms")
    assert not near({**report, "rms": 0.0079}, 4e-3, True, "rms")
    assert near({**report, "rms": 0.049}, 4e-3, True, "rms")
    assert not near({**report, "rms": 0.051}, 1e-9, True, "rms")
    assert not near({**report, "noise": 0.0}, 0.0, True, "rms")
    assert not near({"rms": 0.03, "diagonal": 10.0}, 4e-3, True, "rms")


def test_the_fold_warning_names_the_causes_the_measured_noise_leaves():
    """``folds_warning``: a mesh's measured noise (``report["noise"]``) at least 0.4 times the
    RMS reached is named first, with its size, and a crushed map second; a mesh measured
    without noise is not told to smooth it; without a measurement (older reports) all three
    causes, ordered by how the fit stopped. (The three causes and the stall's words made
    messages of up to 1150 characters, which Blender's console cut at about 1000: user
    test.)"""
    warn = core.surface.folds_warning
    base = {"folded": 0.02, "rms": 0.01, "stop_reason": "tolerance reached"}
    noisy = warn({**base, "noise": 0.005, "noise_rel": 0.0025})
    assert "the likely causes: the mesh's noise (its vertices scatter 0.25% of the diagonal" \
        in noisy and "narrow fingers" in noisy and "steep slopes" not in noisy
    for clean in (warn({**base, "noise": 0.0, "noise_rel": 0.0}),
                  warn({**base, "noise": 0.003, "noise_rel": 0.0015})):  # below 0.4 x RMS
        assert "noise" not in clean and clean.index("steep slopes") < clean.index("fingers")
    stalled = warn({**base, "stop_reason": "the error stopped falling", "noise": 0.0,
                    "noise_rel": 0.0})
    assert "noise" not in stalled and stalled.index("fingers") < stalled.index("steep slopes")
    older = warn(base)
    assert older.index("steep slopes") < older.index("fingers") < older.index("noisy mesh")
    assert len(noisy) < 600 and len(clean) < 600


def test_few_noisy_points_per_control_point_stop_on_the_error_at_new_points():
    """4000 points with noise 0.01, a tolerance far below it. With 2-6 points per control point
    the training RMS keeps falling as the net fits the noise (knots^-0.13 to -0.38: the run
    took the whole budget, 1980 control points, and ended 0.013 off the true shape), so the
    stall rule compares estimates of the error at new points, ``rms sqrt((1 + p/n) / (1 -
    p/n))``, and returns the fit of the lowest estimate (the probe, 148 control points): 0.002
    off the true shape. The default smoothness of a stalled run is cross-validated (that is for
    clean data with few points per control point: the next test); one given is kept."""
    rng = np.random.default_rng(4000)
    xy = rng.uniform(-1, 1, (4000, 2))
    shape = lambda x, y: 0.3 * np.exp(-4 * (x * x + y * y)) + 0.1 * np.sin(3 * x) * np.cos(2 * y)  # noqa: E731
    noisy = np.c_[xy, shape(*xy.T) + 0.01 * rng.standard_normal(len(xy))]
    surf = fit_surface(noisy, tolerance=1e-4)
    r = surf.report
    assert r["stop_reason"] == "the error stopped falling" and r["control_points"] < 1000
    assert "stopped falling" in r["smoothness_selection"]["why"]
    # the fit returned is the one of lowest estimated error at new points, not the last one
    back = r["history"][r["returned_iteration"] - 1]
    assert back["control_points"] == r["control_points"] < r["history"][-1]["control_points"]
    g = np.linspace(-0.95, 0.95, 60)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    uv = surf.parameterization.project(np.c_[grid, shape(*grid.T)])
    assert np.sqrt(np.mean((surf(uv)[:, 2] - shape(*grid.T)) ** 2)) < 0.0035
    kept = fit_surface(noisy, tolerance=1e-4, smoothness=1e-4).report
    assert kept["smoothness"] == 1e-4 and "smoothness_selection" not in kept


def test_a_tiny_start_is_not_taken_for_a_stall_after_one_insertion():
    """The stall rule's window of insertions that doubled the knots (refine's steps) counts
    from at least MIN_PROBE_KNOTS: from 1 interior knot, one insertion (to 10 knots) made a
    window, and clean Franke stopped as "the error stopped falling" at 23 control points, RMS
    3.7e-2 of the diagonal, with a warning that the cloud may fold (user test)."""
    xy = np.random.default_rng(0).random((3000, 2))
    r = fit_surface(np.c_[xy, franke(*xy.T)], initial_knots=1).report
    assert r["stop_reason"] == "tolerance reached" and r["rms_rel"] <= 1e-3
    assert r["history"][0]["interior_knots"] == 1 and len(r["history"]) > 2


def test_a_stalled_run_on_clean_data_cross_validates_its_default_smoothness():
    """Clean F10 (a cosine peak) on 3000 points with an unreachable tolerance stalls at about
    800 control points (under 4 points each): with the default 1e-4 the surface overshoots in
    the gaps between the points, 0.053 off the function; the cross-validated weight keeps it
    to 0.004."""
    def cosine_peak(x, y):  # Renka-Brown F10: a cone point at the centre
        r = np.sqrt((80.0 * x - 40.0) ** 2 + (90.0 * y - 45.0) ** 2)
        return np.exp(-0.04 * r) * np.cos(0.15 * r)

    xy = np.random.default_rng(0).random((3000, 2))  # benchmarks/datasets.py's sample
    surf = fit_surface(np.c_[xy, cosine_peak(*xy.T)], tolerance=1e-5)
    r = surf.report
    assert r["stop_reason"] == "the error stopped falling"
    assert r["smoothness"] > 1e-4 and "stopped falling" in r["smoothness_selection"]["why"]
    g = np.linspace(0.02, 0.98, 80)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    truth = np.c_[grid, cosine_peak(*grid.T)]
    uv = surf.parameterization.project(truth)
    ok = surf.covers(uv)
    assert np.sqrt(np.mean((surf(uv[ok])[:, 2] - truth[ok, 2]) ** 2)) < 0.01
    # not noise (core.parameterize.local_noise: 0): the CLI and Blender do not call it so
    assert r["noise"] < 0.1 * r["rms"] and not core.surface.stopped_at_noise(r)


@pytest.mark.parametrize("n, error, previous, expected", [
    (40, 8e-3, None, 166),  # far: the automatic start itself (1.1 * 40 * 8^(2/3) = 176)
    (40, 2e-3, None, 70),  # 1.1 * 40 * 2^(2/3) = 69.8, with the smooth rate 3/2
    (40, 5e-3, None, 129),  # 128.7: not rounded up to the start (user test: 1.5x the net)
    (40, 1.05e-3, None, None),  # at most 15% more: go on by insertion
    (40, 2e-3, (20, 4e-3), 88),  # measured rate 1: 1.1 * 40 * 2
    (40, 2e-3, (20, 2.1e-3), 166),  # noise-like rate 0.07, clipped to 0.5: 176
])
def test_next_start_predicts_the_knots_for_the_tolerance(n, error, previous, expected):
    assert next_start(n, error, 1e-3, previous, 2, 166) == expected


@pytest.mark.parametrize("name", ["ridge", "patch-01"])
def test_crease_tcb_beats_dcb_at_equal_control_points(name):
    """On sharp ridges TCB is more accurate than DCB for the same control-point budget.

    (At equal *knots* DCB has ~2.4x as many functions and was measured more accurate; see
    the note of issue 3 and benchmarks/compare.py.)
    """
    points, faces = ridge_cloud(), None
    if name != "ridge":
        points, faces = read_geometry(DATA / f"{name}.off")
    rms = {}
    for mode in ("tcb", "dcb"):
        surf = fit_surface(points, faces, mode=mode, tolerance=0, max_control_points=300)
        assert surf.report["control_points"] <= 300
        rms[mode] = surf.report["rms_rel"]
    assert rms["tcb"] < rms["dcb"], rms


def test_disk_mesh_reconstructs_without_fold_overs(nefertiti):
    points, faces, surf = nefertiti
    assert surf.report["rms_rel"] <= 1e-2
    assert np.nanmax(surf.errors) / surf.report["diagonal"] < 0.05
    # 128 steps resolve the scan's rim, where the surface turns by ~90 degrees within 0.1 of
    # the disk (at 64 steps one rim triangle spans that bend; it is not a fold of the map)
    uv, tri = surf.tessellation_uv(128)
    verts = surf(uv)
    face_n = np.cross(verts[tri[:, 1]] - verts[tri[:, 0]], verts[tri[:, 2]] - verts[tri[:, 0]])
    vert_n = surf.normals(uv)
    assert np.all((face_n[:, None, :] * vert_n[tri]).sum(axis=2) > 0)
    # the surface is oriented like the input mesh
    pf = surf.parameterization.faces
    mesh_n = np.cross(points[pf[:, 1]] - points[pf[:, 0]], points[pf[:, 2]] - points[pf[:, 0]])
    assert np.all((mesh_n * surf.normals(surf.parameterization.uv[pf].mean(axis=1))).sum(1) > 0)
    # the tessellation covers the disk polygon: its area equals the polygon's
    a, b, c = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
    area = 0.5 * np.sum((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    poly = surf.parameterization.domain_polygon
    poly_area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    assert area == pytest.approx(poly_area, rel=1e-9)


def _edge_uses(tri):
    e = np.sort(tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(e, axis=0, return_counts=True)[1]


def test_fine_tessellation_is_a_lattice_inside_and_covers_the_disk_exactly(nefertiti):
    """At resolution 400 the tessellation splits the grid cells deep
    inside the domain into two triangles each and Delaunay-triangulates only the boundary
    strip (``core.surface._lattice``). The pieces must join into one triangulated disk: the
    polygon's area exactly, every triangle CCW, each edge in one or two triangles, Euler
    characteristic 1 (a strip triangle across a lattice cell would overlap it)."""
    _, _, surf = nefertiti
    split = []

    def spy(*args):
        cells, rest, in_cells = lattice(*args)
        split.append(len(cells))
        return cells, rest, in_cells

    lattice = core.surface._lattice
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(core.surface, "_lattice", spy)
        uv, tri = surf.tessellation_uv(400)
    assert split and split[0] > 0.8 * len(tri)  # most triangles are split cells, not qhull's
    a, b, c = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
    doubled = orient2d(a, b, c)
    assert np.all(doubled > 0)
    poly = surf.parameterization.domain_polygon
    poly_area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    assert 0.5 * doubled.sum() == pytest.approx(poly_area, rel=1e-9)
    uses = _edge_uses(tri)
    assert uses.max() == 2
    assert len(np.unique(tri)) == len(uv)
    assert len(uv) - len(uses) + len(tri) == 1
    # most triangles are half-cells of the lattice (legs of one grid step along u and v)
    d = float(np.ptp(poly, axis=0).max()) / 400
    assert np.mean(np.isclose(doubled, d * d, rtol=1e-6)) > 0.9


def test_moving_one_control_point_changes_the_surface_only_on_its_support(nefertiti):
    _, _, surf = nefertiti
    uv, _ = surf.tessellation_uv(64)
    i = len(surf.control_points) // 2
    C = surf.control_points.copy()
    C[i] += [0.0, 0.0, 1.0]
    moved = surf.with_control_points(C)
    change = np.linalg.norm(moved(uv) - surf(uv), axis=1)
    support = surf.evaluation_matrix(uv)[:, i].toarray().ravel() > 0
    assert support.any()
    assert np.all(change[~support] == 0)
    assert np.all(change[support] > 0)
    # the original is unchanged and read-only
    assert not np.array_equal(surf.control_points, C)
    with pytest.raises(ValueError):
        surf.control_points[0, 0] = 1.0


def test_save_load_round_trips_bit_exactly(nefertiti, tmp_path):
    _, _, surf = nefertiti
    path = tmp_path / "surface.npz"
    surf.save(path)
    back = TCBSurface.load(path)
    uv, _ = surf.tessellation_uv(32)
    np.testing.assert_array_equal(back.control_points, surf.control_points)
    np.testing.assert_array_equal(back.knots, surf.knots)
    np.testing.assert_array_equal(back(uv), surf(uv))
    np.testing.assert_array_equal(back.errors, surf.errors)
    np.testing.assert_array_equal(back.control_net()[1], surf.control_net()[1])
    assert back.report == surf.report
    assert TCBSurface.from_bytes(surf.to_bytes()).report == surf.report
    assert TCBSurface.from_bytes(bytearray(surf.to_bytes())).report == surf.report
    # a path given as a str: the error says to load() it (it raised TypeError: user test)
    with pytest.raises(FileFormatError, match=r"must be the bytes .* got str; .*load\(path\)"):
        TCBSurface.from_bytes(str(path))


def _per_point_bytes(data: bytes) -> int:
    """Compressed size of a surface file's per-point arrays (parameters, errors, faces, ...)."""
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return sum(i.compress_size for i in z.infolist()
                   if i.filename.split(".")[0] in ("param_uv", "errors", "param_stretch",
                                                   "param_faces", "param_faces_delta"))


def test_compact_bytes_keep_the_spline_and_round_only_the_data_arrays_to_32_bits(nefertiti, tmp_path):
    """``to_bytes(compact=True)`` / ``save(compact=True)`` (what Blender stores): the knots,
    configurations and control points exact, the data's parameters, errors and stretch rounded
    to float32 (read back as float64), the faces exact; about half the size or less; the
    same bytes' surface again when written compact twice; readable by refine()."""
    cloud = ridge_cloud(4000)
    for points, faces, surf in (nefertiti, (cloud, None, fit_surface(cloud, max_iterations=2))):
        full, compact = surf.to_bytes(), surf.to_bytes(compact=True)
        assert len(compact) < len(full)
        assert _per_point_bytes(compact) < 0.6 * _per_point_bytes(full)
        back = TCBSurface.from_bytes(compact)
        np.testing.assert_array_equal(back.coefficients, surf.coefficients)
        np.testing.assert_array_equal(back.knots, surf.knots)
        for a, b in zip(back.configurations.triangles + back.configurations.interior,
                        surf.configurations.triangles + surf.configurations.interior):
            np.testing.assert_array_equal(a, b)
        assert back.report == surf.report
        p, q = back.parameterization, surf.parameterization
        inner = np.ones(len(q.uv), bool)
        if q.boundary is not None:  # a mesh's boundary rows stay its domain polygon, exactly
            inner[q.boundary] = False
            np.testing.assert_array_equal(p.uv[p.boundary], p.domain_polygon)
            np.testing.assert_array_equal(p.uv[p.boundary], q.uv[q.boundary])
        for name in ("uv", "stretch"):
            if getattr(q, name) is None:
                assert getattr(p, name) is None
                continue
            assert getattr(p, name).dtype == np.float64
            np.testing.assert_array_equal(getattr(p, name)[inner],
                                          getattr(q, name)[inner].astype(np.float32).astype(np.float64))
        assert np.abs(p.uv - q.uv)[q.used].max() <= 6e-8 * np.abs(q.uv[q.used]).max()
        np.testing.assert_array_equal(back.errors, surf.errors.astype(np.float32).astype(np.float64))
        if faces is None:
            assert p.faces is None
        else:
            assert p.faces.dtype == np.int64
            np.testing.assert_array_equal(p.faces, q.faces)
        np.testing.assert_array_equal(p.domain_polygon, q.domain_polygon)
        np.testing.assert_array_equal(p.used, q.used)
        # compact again: the same surface (float32 values survive float64 and back)
        again = TCBSurface.from_bytes(back.to_bytes(compact=True))
        np.testing.assert_array_equal(again.parameterization.uv, p.uv)
        np.testing.assert_array_equal(again.errors, back.errors)
        # the tessellation depends on the data's parameters only through distances: the same
        # mesh here, and the same surface on it
        v1, f1 = surf.tessellate(48)
        v2, f2 = back.tessellate(48)
        np.testing.assert_array_equal(f1, f2)
        np.testing.assert_allclose(v1, v2, rtol=0, atol=1e-12 * np.abs(v1).max())
        assert back.fitted_to(points)
        assert len(back.refine(points, faces, max_iterations=1).control_points) > 0
        with zipfile.ZipFile(io.BytesIO(compact)) as z, z.open("format_version.npy") as fh:
            assert int(np.lib.format.read_array(fh)) == 3  # (4: a flipped mesh's, below)
    # damaged compact faces: a specific error (they were dropped: review)
    arrays = dict(np.load(io.BytesIO(nefertiti[2].to_bytes(compact=True))))
    for bad in (arrays["param_faces_delta"][:, :2], arrays["param_faces_delta"].ravel()):
        buf = io.BytesIO()
        np.savez(buf, **(arrays | {"param_faces_delta": bad}))
        with pytest.raises(FileFormatError, match="damaged or incomplete .its faces"):
            TCBSurface.from_bytes(buf.getvalue())
    path = tmp_path / "small.npz"
    surf.save(path, compact=True)
    assert path.stat().st_size < len(full)
    np.testing.assert_array_equal(TCBSurface.load(path).errors, back.errors)


def test_a_mesh_and_its_flipped_copy_get_the_same_surface_facing_their_ways(nefertiti, tmp_path):
    """The scan and its copy with every face's winding reversed (Blender's Flip Normals, an OBJ
    written the other way) get the same surface: the same control points and values at the
    same parameters, bit for bit (they had 496 and 564 control points), the tessellation's and
    the control net's triangles reversed and the normals negated, each facing the way of its
    faces. The flag survives files (format 4; readers before it refuse them) and refine() with
    each mesh's own faces; the other file has no flag, as files written before it."""
    points, faces, surf = nefertiti
    back = fit_surface(points, faces[:, ::-1], tolerance=1e-3)
    assert surf.parameterization.flipped != back.parameterization.flipped
    np.testing.assert_array_equal(back.control_points, surf.control_points)
    np.testing.assert_array_equal(back.knots, surf.knots)
    assert back.report["control_points"] == surf.report["control_points"]
    v1, f1 = surf.tessellate(40)
    v2, f2 = back.tessellate(40)
    np.testing.assert_array_equal(v2, v1)
    np.testing.assert_array_equal(f2, f1[:, ::-1])
    uv, tri = back.tessellation_uv(40)
    np.testing.assert_array_equal(back(uv), surf(uv))
    np.testing.assert_array_equal(back.normals(uv), -surf.normals(uv))
    n1, n2 = surf.control_net(), back.control_net()
    np.testing.assert_array_equal(n2[0], n1[0])
    np.testing.assert_array_equal(n2[1], n1[1][:, ::-1])

    def vector_area(p, f):
        return np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]).sum(axis=0)

    for s, f, (v, t) in ((surf, faces, (v1, f1)), (back, faces[:, ::-1], (v2, f2))):
        given = vector_area(points, f)
        assert vector_area(v, t) @ given > 0.99 * np.linalg.norm(vector_area(v, t)) * np.linalg.norm(given)
        normal = s.normals(uv[tri].mean(axis=1))  # (the tessellation's normals face its way)
        facing = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        assert np.mean(np.einsum("ij,ij->i", normal, facing) > 0) > 0.99
    for s in (surf, back):
        for compact in (False, True):
            data = s.to_bytes(compact=compact)
            with zipfile.ZipFile(io.BytesIO(data)) as z:
                assert ("param_flipped.npy" in z.namelist()) == s.parameterization.flipped
                with z.open("format_version.npy") as fh:
                    version = int(np.lib.format.read_array(fh))
            assert (version == 4 == FORMAT_VERSION) == s.parameterization.flipped
            loaded = TCBSurface.from_bytes(data)
            assert loaded.parameterization.flipped == s.parameterization.flipped
            np.testing.assert_array_equal(loaded.tessellate(40)[1], s.tessellate(40)[1])
    path = tmp_path / "back.npz"
    back.save(path)
    assert TCBSurface.load(path).parameterization.flipped
    for s, f in ((surf, faces), (back, faces[:, ::-1])):
        refined = s.refine(points, f, max_iterations=1)
        assert refined.parameterization.flipped == s.parameterization.flipped
        # the faces in another order, renumbered into another map (TCBSurface.reordered)
        order = np.random.default_rng(0).permutation(len(f))
        again = s.refine(points, np.roll(f[order], 1, axis=1), max_iterations=1)
        assert again.parameterization.flipped == s.parameterization.flipped
        for r in (refined, again):
            assert vector_area(*r.tessellate(24)) @ vector_area(points, f) > 0
    with pytest.raises(InvalidInputError, match="needs the faces this surface was fitted to"):
        surf.refine(points, faces[:, ::-1], max_iterations=1)  # (the other winding: another mesh)


def test_save_names_what_is_wrong_and_gives_the_file_the_umask_permissions(nefertiti, tmp_path):
    import os

    _, _, surf = nefertiti
    with pytest.raises(InvalidInputError, match=r"\*\.npz \(got face\.obj\)"):
        surf.save(tmp_path / "face.obj")
    with pytest.raises(InvalidInputError, match="the folder .*nope does not exist"):
        surf.save(tmp_path / "nope" / "face.npz")
    assert not list(tmp_path.iterdir())  # no file, no temporary left
    old = os.umask(0o022)
    try:
        surf.save(tmp_path / "face.npz")
    finally:
        os.umask(old)
    assert (tmp_path / "face.npz").stat().st_mode & 0o777 == 0o644
    (tmp_path / "face.npz").chmod(0o600)  # an existing file keeps its mode
    surf.save(tmp_path / "face.npz")
    assert (tmp_path / "face.npz").stat().st_mode & 0o777 == 0o600
    assert [f.name for f in tmp_path.iterdir()] == ["face.npz"]


def test_load_refuses_damaged_and_future_files(nefertiti, tmp_path):
    _, _, surf = nefertiti
    data = surf.to_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(FileFormatError, match="truncated.npz"):
        TCBSurface.load(bad)
    with pytest.raises(FileFormatError, match="no such file"):
        TCBSurface.load(tmp_path / "missing.npz")
    future = tmp_path / "future.npz"
    arrays = dict(np.load(__import__("io").BytesIO(data)))
    arrays["format_version"] = np.array(99)
    np.savez(future, **arrays)
    with pytest.raises(FileFormatError, match="newer"):
        TCBSurface.load(future)
    # entries that load but fail at first use (Blender's Import Spline had made half a result
    # and shown a traceback: user test), a folder, and a DEM grid given for a spline
    report = json.loads(str(arrays["report"]))
    options = json.loads(str(arrays["options"]))
    for name, change, words in (
            ("report", dict(report, rms="abc"), "report's 'rms' is 'abc'"),
            ("report", dict(report, edited=1.5), "report's 'edited' is 1.5"),
            ("options", dict(options, tolerance="x"), "tolerance must be a nonnegative number"),
            ("triangles_1", None, "its triangles_1 are no indices of its knots")):
        damaged = dict(arrays, format_version=np.array(FORMAT_VERSION))
        damaged[name] = (np.array(json.dumps(change)) if change is not None
                         else damaged[name] + len(damaged["knots"]))
        path = tmp_path / "damaged.npz"
        np.savez(path, **damaged)
        with pytest.raises(FileFormatError, match=re.escape(words)):
            TCBSurface.load(path)
    with pytest.raises(FileFormatError, match="is a folder: give the name of a .npz file"):
        TCBSurface.load(tmp_path)
    np.savez(tmp_path / "dem.npz", elevation=np.zeros((3, 3)))
    with pytest.raises(FileFormatError, match=r"is a DEM grid \('elevation'\), not a TCB "):
        TCBSurface.load(tmp_path / "dem.npz")


def test_callback_sees_every_iteration_and_can_cancel():
    points = ridge_cloud(3000)
    seen = []

    def callback(report):
        seen.append(report)
        return len(seen) == 2

    surf = fit_surface(points, tolerance=0, max_iterations=10, callback=callback)
    assert [r["iteration"] for r in seen] == [1, 2]
    assert set(seen[0]) >= {"iteration", "knots", "control_points", "rms", "max", "rms_rel",
                            "max_rel", "seconds"}
    assert surf.report["stop_reason"] == "cancelled"
    assert surf.report["rms"] == pytest.approx(min(r["rms"] for r in seen), rel=1e-9)


def test_same_input_gives_the_same_surface():
    points = ridge_cloud(2000)
    a = fit_surface(points, max_iterations=3)
    b = fit_surface(points, max_iterations=3)
    np.testing.assert_array_equal(a.control_points, b.control_points)


def test_a_cloud_is_checked_once_and_refine_checks_its_points_again():
    """fit_surface skips the second normalize() of a cloud that parameterize() has just
    accepted: the surface is bit-identical to the one made with the check, and refine(), which
    gets the points anew, still refuses bad ones."""
    from core.parameterize import parameterize
    from core.refine import RefineOptions
    from core.surface import _run

    points = ridge_cloud(2000)
    fast = fit_surface(points, max_iterations=2)
    options = RefineOptions(max_iterations=2)
    checked = _run(points, parameterize(points), options, None, checked=False)
    np.testing.assert_array_equal(fast.control_points, checked.control_points)
    bad = points.copy()
    bad[5] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        fast.refine(bad)


def test_refine_checks_the_faces_and_says_that_edits_are_replaced(nefertiti):
    """refine() ignored its faces (any, or faces for a cloud's surface) and dropped edited
    control points without a word (user test): faces other than the fit's are refused, faces
    for a cloud's surface too, and an edited surface's refine() warns that the edits go."""
    points, faces, _ = nefertiti
    surf = fit_surface(points, faces, max_control_points=150, max_iterations=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # (no edits: no warning)
        same = surf.refine(points, faces, max_iterations=1)
    np.testing.assert_array_equal(same.control_points,
                                  surf.refine(points, max_iterations=1).control_points)
    for other in (faces[:10], faces[:, [0, 2, 1]]):  # (faces[::-1]: taken, test_surface_api)
        with pytest.raises(InvalidInputError, match="needs the faces this surface was fitted to"):
            surf.refine(points, other, max_iterations=1)
    # the faces as given, not the fit's cleaned ones: a repeated face and a flipped one are
    # dropped and turned by the fit, and the same faces are still the same (review)
    messy = np.vstack([faces[:1, ::-1], faces[1:], faces[5:6]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        tidy = fit_surface(points, messy, max_control_points=150, max_iterations=1)
    tidy.refine(points, messy, max_iterations=1)
    tidy.refine(points, messy.astype(float), max_iterations=1)  # (whole floats: the same)
    cloud = ridge_cloud(600)
    with pytest.raises(InvalidInputError, match="fitted to a point cloud: give its points only"):
        fit_surface(cloud, max_iterations=1).refine(cloud, np.array([[0, 1, 2]]))
    edited = surf.with_control_points(surf.control_points + [0.0, 0.0, 0.01])
    with pytest.warns(RuntimeWarning, match=rf"{len(surf.control_points)} edited control points "
                                            r"are replaced: refine\(\) fits the data again"):
        again = edited.refine(points, faces, max_iterations=1)
    np.testing.assert_array_equal(again.control_points, same.control_points)
    # and after a save and a load (user test: the edits were then replaced with no word)
    for compact in (False, True):
        kept = TCBSurface.from_bytes(edited.to_bytes(compact=compact))
        assert kept.fitted_to(points) and (compact or kept.to_bytes() == edited.to_bytes())
        with pytest.warns(RuntimeWarning, match="edited control points are replaced"):
            kept.refine(points, faces, max_iterations=1)


def test_refine_continues_with_a_tighter_tolerance():
    points = ridge_cloud(3000)
    coarse = fit_surface(points, max_iterations=2, tolerance=0)
    fine = coarse.refine(points, max_iterations=3, tolerance=0)
    assert fine.report["iterations"] == 5
    assert fine.report["rms"] < coarse.report["rms"]
    assert len(fine.knots) > len(coarse.knots)


def test_refine_never_returns_a_surface_worse_than_the_one_it_started_from(monkeypatch):
    """A noisy sphere cap fitted at 3e-3 (49 control points, RMS 1.58e-3 of the diagonal),
    refined at half its error as Blender's Refine does, from the compact stored spline: the
    tighter tolerance makes the vertices' noise count (core.surface.mesh_noise_counts), and
    with a noisy mesh's faces always sampled flat (as through the thirty-seventh session; now
    this cap's stay curved: the next test) the refit at the same knots was 2.36e-3, the run's
    choice (lowest estimated error, 65 control points) 1.83e-3, returned as the refined surface
    (user test). The surface it started from is returned instead, with its errors, and the
    report says so."""
    monkeypatch.setattr(core.surface, "FACET_SAG_OVER_NOISE", np.inf)
    points, faces = noisy_sphere_cap()
    fit = fit_surface(points, faces, tolerance=3e-3, max_control_points=400)
    r0 = fit.report
    stored = TCBSurface.from_bytes(fit.to_bytes(compact=True))
    refined = stored.refine(points, faces, rounding=1e-6, tolerance=0.5 * r0["rms_rel"],
                            max_control_points=max(400, 2 * r0["control_points"]),
                            max_iterations=20)
    r = refined.report
    assert r["rms"] <= r0["rms"] * (1 + 1e-6)  # (the stored errors: 32-bit floats)
    assert r["iterations"] > r0["iterations"]  # ... after a run whose fits were all worse
    assert all(h["rms"] > r0["rms"] for h in r["history"][r0["iterations"]:])
    kept = r["kept_start"]
    assert kept["criterion"] == "rms" and kept["refined"] > kept["start"] == r["rms"]
    assert np.array_equal(refined.coefficients, stored.coefficients)
    assert np.array_equal(refined.knots, stored.knots)
    assert r["control_points"] == r0["control_points"]
    assert r["returned_iteration"] == r0["returned_iteration"] < r["iterations"]
    np.testing.assert_allclose(refined.errors, fit.errors, rtol=1e-5, atol=1e-7)
    assert "the surface refine started from" in refine.returned_why(r)
    # ... in words that do not contradict themselves where the two errors print alike (a
    # stalled run's refit of the same net: "a higher RMS, 0.00389 against 0.00389"; user test)
    alike = dict(kept, refined=kept["start"] * (1 + 1e-6))
    assert refine.kept_words(alike) == f"is no better (RMS {kept['start']:.4g})"
    assert refine.kept_words(dict(kept, refined=2 * kept["start"])).startswith("has a higher RMS")


def off_unit_sphere(surf, faces) -> float:
    """The RMS distance from the unit sphere of ``surf`` (a fit of a sphere cap's mesh with
    ``faces``) at 20 000 seeded random points of the faces' parameters, over the diagonal."""
    uv = np.asarray(surf.parameterization.uv)
    rng = np.random.default_rng(5)
    corners = uv[faces[rng.integers(len(faces), size=20_000)]]
    at = surf((corners * rng.dirichlet([1, 1, 1], 20_000)[:, :, None]).sum(axis=1))
    return np.sqrt(np.mean((np.linalg.norm(at, axis=1) - 1.0) ** 2)) / surf.report["diagonal"]


def test_a_noisy_mesh_has_no_more_control_points_than_vertices(monkeypatch):
    """The noisy sphere cap (193 vertices, noise 0.5% of the radius) at 1e-4, far below its
    noise: its faces' samples are its vertices interpolated, and without a cap on the net
    (refine.NOISY_NET_PER_VERTEX) the run fitted the noise with 1402 control points (fresh
    starts sized for the tolerance jump past the window the stall test needs), 1.59e-3 of the
    diagonal from the sphere. Now the error stops falling with at most one control point per
    vertex (97), closer to the sphere, at both tolerances."""
    points, faces = noisy_sphere_cap(noise=0.005)
    nets = {}
    for tol in (1e-3, 1e-4):
        surf = fit_surface(points, faces, tolerance=tol)
        r = surf.report
        assert r["stop_reason"] == refine.STALLED and r["control_points"] <= len(points)
        nets[tol] = (r["control_points"], off_unit_sphere(surf, faces))
    assert nets[1e-3] == nets[1e-4]
    monkeypatch.setattr(refine, "NOISY_NET_PER_VERTEX", np.inf)
    chased = fit_surface(points, faces, tolerance=1e-4)
    assert chased.report["control_points"] > 5 * len(points)
    assert off_unit_sphere(chased, faces) > 1.3 * nets[1e-4][1]


def test_a_noisy_mesh_s_net_at_its_cap_is_a_stall_that_returns_the_lowest_estimate(monkeypatch):
    """Where the loop reaches the cap on a noisy mesh's net (here a third of a control point
    per vertex, the stall test off so that only the cap stops it), the run is stalled, says the
    cap (report["net_capped"]), and returns the fit of the lowest estimated error at new points
    as the stall test's stop does, not the largest net's lower RMS (a review: the cap's stop had
    returned the net that fits the most noise, called "lowest estimated error")."""
    monkeypatch.setattr(refine, "NOISY_NET_PER_VERTEX", 0.3)
    monkeypatch.setattr(refine, "_stalled", lambda *a, **k: False)
    points, faces = noisy_sphere_cap(noise=0.005)
    r = fit_surface(points, faces, tolerance=1e-4).report
    assert r["stop_reason"] == refine.STALLED and r["net_capped"] == int(0.3 * len(points))
    assert r["control_points"] <= r["net_capped"] and "net_capped" in r["history"][-1]
    lowest = min(r["history"], key=lambda h: h["rms"])
    assert r["returned_iteration"] < r["iterations"] == lowest["iteration"]
    assert refine.returned_why(r) == "lowest estimated error"


def test_a_noisy_coarse_mesh_of_a_curved_shape_is_fitted_as_the_shape_not_its_facets(monkeypatch):
    """The noisy sphere cap (32 x 16 segments, noise 0.002 of the radius) at a tolerance where
    its noise counts: the facets' sag (core.surface.facet_sag, 2.5x its noise) outweighs the
    noise, so its faces are sampled curved as a clean mesh's are. Sampled flat (as through the
    thirty-seventh session) the fit at 7.9e-4 was 1.69e-3 of the diagonal from the sphere
    (curved: 3.98e-4), and Refine from the fit at 3e-3 kept its start (every refined surface
    worse); now it refines to half the RMS and closer to the sphere. A dense noisy grid, whose
    facets hardly sag, keeps its flat samples."""
    points, faces = noisy_sphere_cap()
    off_sphere = lambda surf: off_unit_sphere(surf, faces)  # noqa: E731
    start = fit_surface(points, faces, tolerance=3e-3, max_control_points=400)
    tight = 0.5 * start.report["rms_rel"]
    now = fit_surface(points, faces, tolerance=tight, max_control_points=400)
    assert now.report["noise_rel"] >= core.surface.NOISE_COUNTS * tight  # (the noise counts)
    assert now.report["face_samples"] == "curved"
    refined = start.refine(points, faces, tolerance=tight, max_control_points=400)
    assert "kept_start" not in refined.report
    assert refined.report["rms"] < 0.6 * start.report["rms"]
    assert off_sphere(refined) < 0.8 * off_sphere(start)
    with monkeypatch.context() as m:
        m.setattr(core.surface, "FACET_SAG_OVER_NOISE", np.inf)
        flat = fit_surface(points, faces, tolerance=tight, max_control_points=400)
    assert flat.report["face_samples"] == "flat"
    assert off_sphere(now) < 6e-4 and 3 * off_sphere(now) < off_sphere(flat)
    grid, grid_faces = noisy_grid(41, 0.002)
    dense = fit_surface(grid, grid_faces, tolerance=1e-3)
    assert dense.report["noise_rel"] > 1e-3 and dense.report["face_samples"] == "flat"


def test_a_sparse_cloud_gets_a_cross_validated_smoothness_unless_one_is_given(monkeypatch):
    """60 random points of Franke's function, about 1 per control point: with smoothness
    1e-4 the surface swings away from the function between the points (seeds 1-5: up to 0.32-
    1.16 of the height range; before the points were fitted in an order of their coordinates
    up to 4.3); the default is cross-validated there (errors 0.19-0.37 of the range). A value
    given explicitly is used as given, with a warning. (The loop's taking back of insertions
    that swing, on by default, keeps this one closer: 0.21 of the range against 0.88.)"""
    import warnings

    xy = np.random.default_rng(1).random((60, 2))
    P = np.c_[xy, franke(*xy.T)]
    zr = np.ptp(P[:, 2])

    def worst_error(surf):  # over the tessellation, against the function itself
        V, _ = surf.tessellate(48)
        return np.abs(V[:, 2] - franke(V[:, 0], V[:, 1])).max() / zr

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        default = fit_surface(P)
    sel = default.report["smoothness_selection"]
    assert 2 * default.report["control_points"] > 60 and "sparse data" in sel["why"]
    assert default.report["smoothness"] == sel["chosen"] >= 1e-2
    assert worst_error(default) < 0.3
    with pytest.warns(RuntimeWarning):
        taken_back = fit_surface(P, smoothness=1e-4)
    assert taken_back.report["smoothness"] == 1e-4
    monkeypatch.setattr(refine, "REVERT_SWINGS", False)
    with pytest.warns(RuntimeWarning) as caught:
        given = fit_surface(P, smoothness=1e-4)
    assert worst_error(taken_back) < 0.5 < worst_error(given)
    said = [str(w.message) for w in caught]
    assert any(re.search(r"60 points for \d+ control points.*overshoot.*'auto'", t) for t in said)
    assert given.report["smoothness"] == 1e-4 and "smoothness_selection" not in given.report
    assert worst_error(given) > 3 * worst_error(default)
    # the swing check (core.surface.data_swings) sees it too; the cross-validated one is clean
    assert given.report["swings"]["places"] > 0 and any("swings away" in t for t in said)
    assert default.report["swings"]["places"] == 0

    # a saved surface remembers that its smoothness was the default: refine() chooses again
    back = TCBSurface.from_bytes(default.to_bytes())
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        again = back.refine(P)
    assert "sparse data" in again.report["smoothness_selection"]["why"]
    with pytest.warns(RuntimeWarning) as caught:
        assert TCBSurface.from_bytes(given.to_bytes()).refine(P).report["smoothness"] == 1e-4
    assert any("only the smoothness 0.0001" in str(w.message) for w in caught)

    xy = np.random.default_rng(1).random((3000, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        dense = fit_surface(np.c_[xy, franke(*xy.T)], max_control_points=400)
    assert dense.report["smoothness"] == 1e-4 and "smoothness_selection" not in dense.report


def test_loose_vertices_of_a_mesh_are_counted_and_few_faced_vertices_refused():
    """A mesh is fitted through its faces: a loose vertex is left out with a warning and
    counted in the report; a mesh whose faces hold fewer than 10 of its many vertices gets an
    error that says so (it had been 'at least 10 points are needed; got 3')."""
    g = np.stack(np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 12)), -1).reshape(-1, 2)
    V = np.c_[g, 0.1 * g[:, 0] ** 2]
    i = np.arange(144).reshape(12, 12)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    F = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    with pytest.warns(RuntimeWarning, match="1 of the 145 vertices is in no face and was left out"):
        surf = fit_surface(np.r_[V, [[0.5, 0.5, 50.0]]], F, max_control_points=100)
    assert surf.report["loose_vertices"] == 1 and surf.report["points"] == 144
    # the stray vertex changed nothing: the same surface as the mesh without it
    assert np.array_equal(surf.control_points, fit_surface(V, F, max_control_points=100).control_points)
    with pytest.raises(InvalidInputError, match="only 3 of the 144 vertices are in faces"):
        fit_surface(V, [[0, 1, 13]])


def test_area_weights_are_one_for_even_clouds_and_follow_the_density_for_uneven_ones():
    """A point's area weight is its cell's covered area over its cell's count (mean 1): near 1
    everywhere for random, grid and disk samples (the border cells are cut to what the data
    covers), and near 4:1 across a 1:4 density step (3.25 expected: the sparse side's cells of
    ~26 points occupy 13.0 of their 16 sub-cells on average, and so count a little less area),
    on a square and on domains 20 and 1000 times as long as wide (about n / 64 square cells on
    each: the 20:1 domain had 17 x 1 cells of about 1200 points before), and for degenerate
    extents (one point, identical points) weights of 1."""
    rng = np.random.default_rng(0)
    g = np.linspace(0, 1, 120)
    angle, radius = rng.random(20_000) * 2 * np.pi, np.sqrt(rng.random(20_000))
    for uv in (rng.random((20_000, 2)), np.c_[np.repeat(g, 120), np.tile(g, 120)],
               np.c_[radius * np.cos(angle), radius * np.sin(angle)]):
        w = area_weights(uv)
        assert abs(w.mean() - 1) < 1e-12 and np.mean(w * w) < 1.05 < UNEVEN_DENSITY
    for length in (1, 20, 1000):
        w = area_weights(rng.random((20_000, 2)) * [length, 1])
        assert np.mean(w * w) < 1.05
        step = np.vstack([rng.random((4000, 2)) * [length / 2, 1],
                          rng.random((16_000, 2)) * [length / 2, 1] + [length / 2, 0]])
        w = area_weights(step)
        inner = np.abs(step[:, 0] / length - 0.5) > 0.1  # away from the step
        ratio = np.median(w[:4000][inner[:4000]]) / np.median(w[4000:][inner[4000:]])
        assert 2.9 < ratio < 3.7 and UNEVEN_DENSITY < np.mean(w * w) < 1.5
    for degenerate in (np.zeros((1, 2)), np.ones((5, 2)), rng.random((50, 2)) * 1e-200):
        assert np.allclose(area_weights(degenerate), 1.0)


def test_a_cloud_of_uneven_density_meets_the_tolerance_over_its_area_too():
    """20 000 points where a scanner dwelt (1 m across) and 1000 over the 100 m tile: the fit
    met the tolerance for the points on 146 control points, the tile's points missing it 3.3x
    (the dense cluster is nearly all of the RMS over points). The RMS over the area must meet
    it too, and the knots go where it is missed."""
    rng = np.random.default_rng(0)
    xy = np.vstack([rng.normal(50, 0.5, (20_000, 2)), rng.uniform(0, 100, (1000, 2))])
    surf = fit_surface(np.c_[xy, 3 * np.sin(xy[:, 0] / 8)], tolerance=1e-3)
    r = surf.report
    tol = 1e-3 * r["diagonal"]
    tile = np.sqrt(np.mean(surf.errors[20_000:] ** 2))
    assert r["rms_area"] <= tol and tile <= tol and r["stop_reason"] == "tolerance reached"
    assert r["history"][-1]["rms_area"] == pytest.approx(r["rms_area"], rel=1e-6)
    assert r["history"][0]["rms_area"] > tol  # the first fit met it only over the points
    assert r["history"][0]["rms"] <= tol


def test_thin_data_replace_the_default_only_when_it_cross_validates_clearly_worse():
    """2-4 points per control point (core.refine.THIN_POINTS_PER_CONTROL): 1000 random DEM
    nodes swing between the nodes with 1e-4 (held-out worst 2281 m on 0.8 km of relief); the
    default's cross-validated error is 3.9x the choice's, so it is replaced, and the held-out
    points inside the domain come 2x closer at worst. 1000 clean points of Franke's function
    (3 per control point) score the default within 1.25x: it stays."""
    pts, _ = read_geometry(DATA / "jacksboro_fault_dem.npz")
    idx = np.random.default_rng(1).permutation(len(pts))
    train, held = pts[idx[:1000]], pts[idx[1000:21000]]

    def held_out(surf):
        uv = surf.parameterization.project(held)
        inside = surf.domain_contains(uv)
        d = np.abs(surf(uv[inside])[:, 2] - held[inside, 2])
        return np.sqrt(np.mean(d**2)), d.max()

    surf = fit_surface(train)
    r = surf.report
    assert 2 <= 1000 / r["control_points"] < 4
    why = r["smoothness_selection"]["why"]
    assert why.startswith("sparse data") and "fewer than 4 each" in why and r["smoothness"] >= 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        given = fit_surface(train, smoothness=1e-4)
    (rms, top), (rms_given, top_given) = held_out(surf), held_out(given)
    assert rms < 0.8 * rms_given and top < 0.5 * top_given  # 70/366 m against 117/2281 m
    # clean data: the default is replaced only where it cross-validates over 1.25x worse, and
    # on most samples it stays (which ones depends on the sample and the parameter axes:
    # seeds 0-3 with x and y as the axes, 2.57 and 1.47x on the first two, kept on the others)
    kept = 0
    for seed in range(4):
        xy = np.random.default_rng(seed).random((1000, 2))
        clean = fit_surface(np.c_[xy, franke(*xy.T)], projection="z")
        assert 2 <= 1000 / clean.report["control_points"] < 4
        sel = clean.report.get("smoothness_selection")
        if sel is None:
            kept += clean.report["smoothness"] == 1e-4
        else:
            cv = sel["cross_validated_rms"]
            assert cv["0.0001"] > 1.25 * min(cv.values()), (seed, cv)
    assert kept >= 2


def test_noise_in_the_sparse_part_of_an_uneven_cloud_is_not_fitted():
    """The dwell cloud with noise of twice the tolerance on the tile's 1000 points: the RMS
    over the area cannot honestly meet the tolerance. Steering the knots by it fitted the noise
    (1000 control points, 9 fits, 6x the tolerance off the true shape; without the area RMS
    150 and 2.7x): a run stops when the estimate of the error at new points over the area
    stops falling, with the area weights' effective count of points (about the tile's). Off
    the true shape: 1.18-1.47x the tolerance over the noise's seeds 7-10 (1.00-1.56x before
    the points were fitted in an order of their coordinates)."""
    rng = np.random.default_rng(0)
    xy = np.vstack([rng.normal(50, 0.5, (20_000, 2)), rng.uniform(0, 100, (1000, 2))])
    pts = np.c_[xy, 3 * np.sin(xy[:, 0] / 8)]
    tol = 1e-3 * np.linalg.norm(np.ptp(pts, axis=0))
    pts[20_000:, 2] += np.random.default_rng(7).normal(0, 2 * tol, 1000)
    surf = fit_surface(pts, tolerance=1e-3)
    r = surf.report
    assert r["stop_reason"] == "the error stopped falling" and r["control_points"] < 450
    assert 1.5 * tol < r["rms_area"] < 2.5 * tol  # the noise, not fitted
    g = np.random.default_rng(3).uniform(5, 95, (5000, 2))
    s = surf(surf.parameterization.project(np.c_[g, 3 * np.sin(g[:, 0] / 8)]))
    assert np.sqrt(np.mean((s[:, 2] - 3 * np.sin(s[:, 0] / 8)) ** 2)) < 1.6 * tol


def step_tile(n: int = 10_000, seed: int = 0) -> np.ndarray:
    """A 200 m terrain tile with a 20 m step along a line and 5 cm noise (user test)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 200, (n, 2))
    z = (0.05 * xy[:, 0] + 5 * np.sin(xy[:, 1] / 30) + 20.0 * (xy[:, 0] + 0.3 * xy[:, 1] > 120)
         + rng.normal(0, 0.05, n))
    return np.c_[xy, z]


def test_a_surface_that_swings_away_between_the_data_is_reported(monkeypatch):
    """A 20 m step fitted along the vertical is a discontinuity: the knots crowd at it until
    functions hold data only at their edges, and the surface swung 70-90 m beyond the data
    between points 1 m apart while the errors at the data stayed under 9 m and nothing was
    said (user test). data_swings finds such places (the surface farther from the segment
    between two neighbouring points than they are apart); the report has them and a
    RuntimeWarning says what to change. With a looser tolerance the same data does not swing
    (nor do the benchmark's smooth and sharp datasets: data_swings' docstring). The loop
    now takes such insertions back (next test): switched off here, so that the report is
    tested on a surface that swings (a fresh start can still)."""
    monkeypatch.setattr(refine, "REVERT_SWINGS", False)
    tile = step_tile()
    # (a smoothness given: the default would be replaced by a smoother one, next test)
    with pytest.warns(RuntimeWarning, match="swings away from the data between neighbouring "
                                            "points at [0-9]+ of the [0-9]+ places checked"):
        surf = fit_surface(tile, tolerance=0.1, relative=False, projection="z",
                           max_control_points=1000, smoothness=1e-4)
    sw = surf.report["swings"]
    assert sw["places"] > 0 and sw["largest"] > 5.0  # metres beyond the data
    # the places checked are a random sample, whatever the order of the points (a scan line
    # by line): the same fit checked with its points sorted along x still shows them
    order = np.argsort(tile[:, 0])
    full = np.zeros((surf.space.n_basis, 3))
    full[surf.active] = surf.control_points
    assert data_swings(surf.space, full, surf.parameterization.uv[order], tile[order],
                       surf.errors[order])[0] > 0
    # exact data with duplicated points (zero-length segments) is no swing
    xy = np.random.default_rng(1).random((500, 2))
    plane = np.c_[xy, 0.3 * xy[:, 0] + 0.2 * xy[:, 1]] + 1000.0
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        flat = fit_surface(np.vstack([plane, plane[:100]]), max_control_points=200)
    assert flat.report["swings"]["places"] == 0
    uv, _ = surf.tessellation_uv(300)
    assert surf(uv)[:, 2].max() > 35.0 + sw["largest"] / 2  # it is really there (data: <= 35)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        loose = fit_surface(tile, tolerance=1.0, relative=False, projection="z",
                            max_control_points=1000)
    assert loose.report["swings"]["places"] == 0 and loose.report["swings"]["checked"] > 0
    assert np.ptp(loose(loose.tessellation_uv(300)[0])[:, 2]) < 42.0  # data: 40


def test_a_few_stray_returns_inside_a_cloud_are_named_after_the_fit():
    """10 stray returns 50-200 m over 4e4 lidar points of a 2 km tile (user test) made 127 m
    spikes in the surface and more than twice the control points, and nothing said so unless
    drop_outliers was given (whose spike test would have found them). The points the fit
    misses most are now tested as spikes: a warning names them and the option; the report
    counts them (``spikes``); none on the same tile without them (nor on compare.py's clouds:
    core.surface.data_spikes)."""
    rng = np.random.default_rng(0)
    xy = rng.random((10_000, 2)) * 2000
    z = 100 * np.sin(xy[:, 0] / 300) + 60 * np.cos(xy[:, 1] / 250) + rng.normal(0, 0.1, len(xy))
    stray = z.copy()
    hit = rng.choice(len(z), 5, replace=False)
    stray[hit] += rng.uniform(100, 200, 5)  # (3-10 times the spacing, 20 m, above it)
    kw = dict(tolerance=0.3, relative=False, projection="z", max_control_points=1000)
    with pytest.warns(RuntimeWarning, match=r"^5 points stick out of the surface of their "
                                            r"neighbours like spikes \(missed by up to [0-9.]+\)"
                                            r": stray returns\?.*drop_outliers=True"):
        surf = fit_surface(np.c_[xy, stray], **kw)
    assert surf.report["spikes"] == 5
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert fit_surface(np.c_[xy, z], **kw).report["spikes"] == 0
        dropped = fit_surface(np.c_[xy, stray], drop_outliers=True, **kw)
    assert "spikes" not in dropped.report and dropped.report["outliers"] == 5


def test_every_spike_the_fit_misses_is_counted_and_not_taken_for_a_fold():
    """30 spikes of +5 among 1e4 points of a smooth terrain, each missed by about 5: the
    check had tested the worst 0.1% only and counted 10; 10 spikes among 3000 points of
    sin(3x) were counted as 3, and a second warning blamed a fold over the projection plane
    and advised projection= (user test). All are counted now, and only the spikes are named."""
    rng = np.random.default_rng(3)
    xy = rng.random((10_000, 2)) * 100
    z = 5 * np.sin(xy[:, 0] / 15) * np.cos(xy[:, 1] / 20)
    hit = rng.choice(len(z), 30, replace=False)
    z[hit] += 5.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        surf = fit_surface(np.c_[xy, z], tolerance=0.01, relative=False)
    assert (surf.errors[hit] > 2).all() and surf.report["spikes"] == 30
    assert any(str(w.message).startswith("30 points stick out") for w in caught)
    xy = np.random.default_rng(3).random((3000, 2))
    z = np.sin(3 * xy[:, 0])
    hit = np.arange(0, 3000, 300)
    z[hit] += 5.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        surf = fit_surface(np.c_[xy, z])
    said = [str(w.message) for w in caught]
    assert surf.report["spikes"] == 10 and said[0].startswith("10 points stick out"), said
    assert not any("fold" in m for m in said), said


@pytest.mark.parametrize("smoothness, beyond", [(0.0, 1.0)])
def test_a_mesh_flaring_out_at_its_border_is_reported(smoothness, beyond, monkeypatch):
    """nefertiti.off fitted with smoothness 0 (the Blender option offers it) reached its
    tolerance, max error 0.3% of the diagonal, while the surface flared out to z = 20-27 at
    its border, 3 diagonals off the scan (1e-7: 0.2 diagonals), between the boundary vertices
    where the midpoint checks did not look: "tolerance reached", no warning (Blender user
    test). The final check now also looks along the border and over the whole domain
    (core.refine._domain_checks); a smoothness given is kept, with the warning. The face's
    boundary on the circle is what made it flare: with its own shape flattened (the default
    now) the surface stays within the scan's extent (a swing of at most 0.5% of the
    diagonal). (So does it on the circle since the face samples lie on curved triangles
    through the vertices,
    core.surface.curved_points: the flare is made here with the flat faces' samples, and with
    seed 6: since the circle starts at the boundary vertex of least coordinates, the default
    seed's knots do not make it flare; of seeds 1-7, 6 does, 5.2 times the scan's extent. With
    smoothness 1e-7, the case this test also had, none of seeds 0-15 flares beyond the scan's
    extent now: seed 4 swings 3.6% of the diagonal inside it, reported.) The face check
    (core.surface.FaceCheck) takes the flare out too: with it, none of seeds 0-7 goes beyond
    the scan's extent (seed 3 swings 3.8% of the diagonal inside it; /tmp/s42/flare.py of
    the forty-second session). The flare is made with the check off; seed 6 is fitted with
    it on as well."""
    import core.parameterize as pz
    import core.surface as surface_module

    points, faces = read_geometry(DATA / "nefertiti.off")
    samples = surface_module.mesh_samples
    with monkeypatch.context() as m, pytest.warns(RuntimeWarning, match="swings away from"):
        m.setattr(pz, "FLAT_BOUNDARY", False)
        m.setattr(surface_module, "mesh_samples",
                  lambda *a, **k: samples(*a, **{**k, "curved": False}))
        m.setattr(surface_module, "FACE_CHECK", False)
        surf = fit_surface(points, faces, smoothness=smoothness, seed=6)
    sw = surf.report["swings"]
    assert sw["places"] > 0 and sw["largest_rel"] > beyond
    assert surf.report["smoothness"] == smoothness
    v, _ = surf.tessellate(128)
    assert np.ptp(v, axis=0).max() > (1 + beyond) * np.ptp(points, axis=0).max()  # it is there
    with monkeypatch.context() as m, warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        m.setattr(pz, "FLAT_BOUNDARY", False)
        m.setattr(surface_module, "mesh_samples",
                  lambda *a, **k: samples(*a, **{**k, "curved": False}))
        checked = fit_surface(points, faces, smoothness=smoothness, seed=6)
    assert sum(h.get("stray_samples", 0) for h in checked.report["history"]) > 0
    v, _ = checked.tessellate(128)
    assert np.ptp(v, axis=0).max() < 1.005 * np.ptp(points, axis=0).max()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        flat = fit_surface(points, faces, smoothness=smoothness)
    # (with no fairing at all it may swing a little between points: 1 place, 1.3e-3 of the
    # diagonal, on the C^1 face samples of the thirty-second session; 0 before)
    assert flat.report["swings"]["largest_rel"] < 5e-3
    v, _ = flat.tessellate(128)
    assert np.ptp(v, axis=0).max() < 1.005 * np.ptp(points, axis=0).max()


def test_a_steep_surface_bending_between_points_of_its_hull_is_no_swing():
    """Renka's F7 with 3x its heights on 5000 random points: between neighbouring points of
    the convex hull 0.3 apart the surface bends up to 5.9 off their chord, as the function
    does. The chord rule alone flagged 6 such places, and a default fit then had its
    smoothness replaced by 100 (1.0 RMS off the function instead of 0.03). A hull place is
    flagged only when the surface is also outside the slab of its nearest data points (the
    flaring mesh above still is)."""
    xy = np.random.default_rng(0).random((5000, 2))  # benchmarks/datasets.py's sample

    def f7(x, y):
        return 3.0 * (2.0 * np.cos(10 * x) * np.sin(10 * y) + np.sin(10 * x * y))

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        surf = fit_surface(np.c_[xy, f7(*xy.T)], smoothness=1e-3)
    assert surf.report["swings"]["places"] == 0 and surf.report["swings"]["checked"] > 5000
    g = np.linspace(0.02, 0.98, 60)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    truth = np.c_[grid, f7(*grid.T)]
    uv = surf.parameterization.project(truth)
    ok = surf.covers(uv)
    d = surf(uv[ok])[:, 2] - truth[ok, 2]
    assert ok.mean() > 0.99
    assert np.sqrt(np.mean(d**2)) < 0.03 and np.abs(d).max() < 0.2  # of 15 (0.015, 0.083)


def test_an_insertion_that_makes_the_surface_swing_is_taken_back(monkeypatch):
    """The step tile of the test above: each insertion after which the surface swings between
    the data (core.refine.swing_places) is taken back and made again away from the places
    that swung, so the surface returned does not swing, stays within the data's heights, and
    is closer to the true shape away from the step than the surface that swings (its largest
    error there is ringing at 3 m from the step)."""
    tile = step_tile()
    truth = lambda x, y: 0.05 * x + 5 * np.sin(y / 30) + 20.0 * (x + 0.3 * y > 120)  # noqa: E731

    def fit(**kw):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return fit_surface(tile, tolerance=0.1, relative=False, projection="z",
                               max_control_points=1000, **kw)

    def off_beyond_the_step(surf):  # RMS and max off the true shape beyond 3 m of the step
        v = surf(surf.tessellation_uv(300)[0])
        far = (np.abs(v[:, 0] + 0.3 * v[:, 1] - 120) / np.hypot(1, 0.3) > 3) & (
            (v[:, :2] > 5).all(axis=1) & (v[:, :2] < 195).all(axis=1))  # (not at the border)
        d = np.abs(v[far, 2] - truth(v[far, 0], v[far, 1]))
        return np.sqrt(np.mean(d**2)), d.max()

    surf = fit()
    r = surf.report
    back = [h for h in r["history"] if "knots_taken_back" in h]
    assert back and all(h["swings"] > 0 and h["knots_taken_back"] > 0 for h in back)
    assert r["returned_iteration"] not in {h["iteration"] for h in back}
    assert r["swings"]["places"] == 0 and r["swings"]["checked"] > 0
    assert surf(surf.tessellation_uv(300)[0])[:, 2].max() < 36.0  # data: <= 35
    monkeypatch.setattr(refine, "REVERT_SWINGS", False)
    swinging = fit(smoothness=1e-4)  # (given: the default would be replaced, below)
    assert swinging.report["swings"]["places"] > 0
    (rms, top), (rms_swinging, top_swinging) = off_beyond_the_step(surf), off_beyond_the_step(swinging)
    # 0.25/8.6 m (0.21/5.1 m before the gap checks took back more insertions near the step),
    # 0.65/39 m
    assert rms < 0.5 * rms_swinging and top < 10.0 < 20.0 < top_swinging
    # the default smoothness of a final surface that swings is replaced by the smallest larger
    # one that does not (core.surface._smoother_if_swinging), and the report says so
    smoother = fit()
    sel = smoother.report["smoothness_selection"]
    assert smoother.report["swings"]["places"] == 0 and smoother.report["smoothness"] > 1e-4
    assert sel["chosen"] == 1e-4 and "with the default 0.0001 the surface swung" in sel["smoother"]
    rms_smoother, top_smoother = off_beyond_the_step(smoother)  # 0.13/2.9 m with 1.0
    assert rms_smoother < 0.5 * rms_swinging and top_smoother < 10.0
    assert smoother(smoother.tessellation_uv(300)[0])[:, 2].max() < 36.0  # data: <= 35
    # the final check reuses the one made on the fit returned (normalized units): it says what
    # checking the surface returned says, also where no smoother one is left to take
    monkeypatch.setattr(core.surface, "AUTO_SMOOTHNESS", ())
    monkeypatch.setattr(core.surface, "SPARSE_SMOOTHNESS", ())
    for s in (surf, smoother, fit()):
        again = data_swings(s.space, s._c, s.parameterization.uv, tile, s.errors, margin=0.1)
        r = s.report["swings"]
        assert (r["places"], r["checked"]) == again[:2] and r["largest"] == pytest.approx(again[2])
    assert r["places"] > 0


def test_a_far_stall_under_a_stiff_smoothness_given_names_it_first():
    """smoothness=1000 on clean Franke stops far from the data; the warning had named only
    folds over the projection plane (user test). It now names the smoothness given first;
    the fold advice follows, as "otherwise"."""
    xy = np.random.default_rng(0).random((3000, 2))
    with pytest.warns(RuntimeWarning, match=r"that is not noise. The smoothness given "
                      r"\(1000, 10000000 times the default\) likely holds") as caught:
        r = fit_surface(np.c_[xy, franke(*xy.T)], smoothness=1000.0).report
    assert r["stop_reason"] == "the error stopped falling"
    assert "Otherwise the cloud may fold" in str(caught[0].message)


def test_an_error_stopped_far_above_the_data_s_scatter_is_warned_of():
    """Renka's F7 on a 71 x 71 grid, turned and with noise of 0.5% of its extent
    (benchmarks/fold_check.py --noisy, case 42): the fold check passes it under the noise,
    though 36% of its triangles flip in the projection, and the fit stopped "the error
    stopped falling" at 12.6% of the diagonal with no word. The data are 3.4% of the
    diagonal from the surface, 8 times their scatter about their local planes (31% of the
    neighbourhoods thin disks): a warning says it is not noise and what to do. The same grid
    as given, and with the noise alone (its errors at the data's parameters are 15 times the
    scatter: the noise across a steep surface over the cosine of its slope; its distances 1.8
    times), fit without it, and so does noise larger than the spacing."""
    g = np.linspace(0.0, 1.0, 71)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    grid = np.c_[xy, 2 * np.cos(10 * xy[:, 0]) * np.sin(10 * xy[:, 1])
                 + np.sin(10 * xy[:, 0] * xy[:, 1])]
    turn, _ = np.linalg.qr(np.random.default_rng(42).normal(size=(3, 3)))
    noise = 0.005 * 5.0 * np.random.default_rng(42).normal(size=grid.shape)
    turned = grid @ turn.T
    turned += 0.005 * np.ptp(turned, axis=0).max() * np.random.default_rng(42).normal(
        size=grid.shape)
    with pytest.warns(RuntimeWarning, match="that is not noise. The cloud may fold") as caught:
        surf = fit_surface(turned)
    r = surf.report
    assert r["stop_reason"] == "the error stopped falling" and r["rms_rel"] > 0.1
    assert r["distance_rms"] > 0.02 * r["diagonal"] and r["distance_rms"] > 6 * r["scatter"]
    assert "projection=" in str([w.message for w in caught if "not noise" in str(w.message)][0])
    # along that direction given: not advised to give one (a fillet's wall edge-on along the
    # z given had been: user test); the report says it was given, for refine() too
    with pytest.warns(RuntimeWarning, match="not be a height field along the direction "
                      "given") as caught:
        given = fit_surface(turned, projection=tuple(surf.parameterization.axes[2]))
    said = str([w.message for w in caught if "not noise" in str(w.message)][0])
    assert "projection=" not in said and "supply a mesh" in said
    assert given.report["projection_given"] and "projection_given" not in r
    assert given.refine(turned, max_iterations=1).report["projection_given"]
    quiet = []
    for points in (grid, grid + noise):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            quiet.append(fit_surface(points).report)
        assert not any("not noise" in str(w.message) for w in caught)
    assert quiet[0]["rms_rel"] < 1e-3 and "distance_rms" not in quiet[0]
    r = quiet[1]
    assert r["stop_reason"] == "the error stopped falling" and r["rms"] > 10 * r["scatter"]
    assert r["distance_rms"] < 0.01 * r["diagonal"] and r["distance_rms"] < 2 * r["scatter"]
    # noise 4 times the spacing (a plane, 20 000 points; review): the 12 nearest points are
    # picked from a layer of the noise and their scatter is 4.2x too small; few of the
    # neighbourhoods are thin disks, and the scatter is not trusted
    rng = np.random.default_rng(0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = fit_surface(np.c_[rng.random((20000, 2)), 0.03 * rng.normal(size=20000)]).report
    assert not any("not noise" in str(w.message) for w in caught)
    assert r["distance_rms"] > 0.01 * r["diagonal"] and r["distance_rms"] > 4 * r["scatter"]
    assert r["scatter_disks"] < 0.1 < 0.3 < surf.report["scatter_disks"]


def test_a_smoother_fit_taken_for_a_swinging_one_loses_at_most_3x_at_the_data(monkeypatch):
    """Without a tolerance reached, the smoother fit that replaces one that swings may miss
    the data by at most SMOOTHER_MAX_LOSS times as much (before: any, and a swing check's
    false places on F7 with 3x its heights gave smoothness 100, 33x the error). Here only
    fits that miss the data by over 3.5x the default's do not 'swing': the default is kept,
    with its swings reported; without the bound a much smoother one was taken."""
    xy = np.random.default_rng(1).random((3000, 2))
    data = np.c_[xy, np.sin(4 * xy[:, 0]) * np.cos(3 * xy[:, 1])]
    first: list = []

    def swinging_unless_far(space, C, uv, points, errors, seed=0, margin=0.0):
        rms = float(np.sqrt(np.mean(np.asarray(errors) ** 2)))
        first.append(rms) if not first else None
        return (0, 10, 0.0) if rms > 3.5 * first[0] else (2, 10, 1e-3)

    monkeypatch.setattr(core.surface, "data_swings", swinging_unless_far)
    with pytest.warns(RuntimeWarning, match="swings away from the data"):
        kept = fit_surface(data, tolerance=0, max_control_points=300)
    assert kept.report["stop_reason"] == "control-point budget reached"
    assert kept.report["smoothness"] == 1e-4 and kept.report["swings"]["places"] == 2
    assert "smoother" not in (kept.report.get("smoothness_selection") or {})
    monkeypatch.setattr(core.surface, "SMOOTHER_MAX_LOSS", np.inf)  # (the rule before)
    first.clear()
    smoother = fit_surface(data, tolerance=0, max_control_points=300)
    assert "smoother" in smoother.report["smoothness_selection"]
    assert smoother.report["swings"]["places"] == 0
    assert smoother.report["rms"] > 3.5 * kept.report["rms"]


def test_a_sizing_restart_that_makes_the_surface_swing_is_taken_back():
    """A 32 x 32 lattice (6.5 m) of a 200 m tile with a 20 m step ending inside it (user
    test): the sizing restart took 128 knots, the surface swung 96 m below and 42 m above
    the data between the lattice points, and every insertion after it was taken back for
    swings that were the restart's own, until the iteration limit; the swinging restart was
    returned (heights -123 to 68 m; switching the taking back off altogether gives a surface
    that does not swing here: the later insertions are then kept). Now the restart is taken
    back (made again with fewer knots) and the surface stays near the data's heights: a C^1
    fit rings at the 20 m step, by up to 2.9 m below and 2.4 m above the data over six seeds
    with the sized start rounded up to the automatic one, 4.0 and 4.8 m since predictions are
    taken as they are (forty-fourth session; this seed: 2.8 and 3.2 m)."""
    g = np.linspace(0, 200, 32)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    z = 5 * np.sin(x / 40) + 3 * np.cos(y / 30) + 20.0 * ((x > 100) & (y > 80))
    lattice = np.c_[x, y, z]

    def heights(surf):
        return surf(surf.tessellation_uv(128)[0])[:, 2]

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        surf = fit_surface(lattice, projection="z")
    r = surf.report
    back = [h for h in r["history"] if "knots_taken_back" in h]
    assert any(h["knots_placed"] == "afresh" for h in back)
    assert r["returned_iteration"] not in {h["iteration"] for h in back}
    assert r["swings"]["places"] == 0
    v = heights(surf)
    assert v.min() > z.min() - 5.0 and v.max() < z.max() + 5.0  # -10.4, 28.9; data -7.5, 25.7


def test_a_run_that_took_back_most_of_its_fits_is_not_told_to_iterate_more():
    """A run that hit its iteration limit while taking back half of its fits or more (user
    test: 18 of 20 at about 415 control points) was told "raise --max-iterations": the CLI
    note and the Blender advice give the swing advice instead (mostly_taken_back)."""
    fits = [{"iteration": k} for k in range(1, 5)]
    back = {"swings": 3, "knots_taken_back": 10}
    half = {"stop_reason": "iteration limit",
            "history": fits[:2] + [{**f, **back} for f in fits[2:]]}
    assert refine.mostly_taken_back(half)
    assert not refine.mostly_taken_back({**half, "stop_reason": "tolerance reached"})
    one = {"stop_reason": "iteration limit", "history": fits[:3] + [{**fits[3], **back}]}
    assert not refine.mostly_taken_back(one)
    assert not refine.mostly_taken_back({"stop_reason": "iteration limit", "history": fits})


def test_insertions_taken_back_again_and_again_end_the_run(monkeypatch):
    """Where every insertion makes the surface swing, the loop took it back and made it again
    to the iteration limit (a spiky terrain: the same fit at iterations 17-20, or 7 in a row
    each a little different), then advised more iterations (user test). Now 4 in a row end
    the run with SWINGS_LEFT, and the fit returned is one that was kept. Here a stand-in for
    swing_places flags a knot of each insertion."""
    from scipy.spatial import cKDTree

    seen = {}

    def every_new_knot_swings(space, C, uv, points, errors, seed=0, margin=0.0):
        K, prev = np.asarray(space.knots), seen.get("knots")
        seen["knots"] = K
        if prev is None:  # the first fit
            return np.zeros((0, 2)), 1, 0.0
        new = K[cKDTree(prev).query(K)[0] > 1e-12]
        return new[:1], 1, 1.0

    monkeypatch.setattr(refine, "swing_places", every_new_knot_swings)
    xy = np.random.default_rng(5).random((3000, 2))
    surf = fit_surface(np.c_[xy, franke(*xy.T)], tolerance=0.0, max_iterations=12)
    r = surf.report
    assert r["stop_reason"] == refine.SWINGS_LEFT
    assert r["iterations"] == 1 + refine.TAKE_BACKS_IN_A_ROW < 12
    assert all("knots_taken_back" in h for h in r["history"][1:])
    assert r["returned_iteration"] == 1
    history = [{"iteration": k} for k in range(1, 7)]
    back = {"swings": 1, "knots_taken_back": 3}
    # (2 of 6 fits taken back, the last two: the swing advice, not "more iterations")
    assert refine.mostly_taken_back({"stop_reason": "iteration limit", "history": history[:4] + [
        {**h, **back} for h in history[4:]]})


class _SpikedPlane:
    """A stand-in for a spline space whose ``evaluate(x) @ np.eye(3)`` is the plane z = 0 with
    a narrow spike of ``height`` at ``centre``: swing_places needs only ``knots`` and that."""

    def __init__(self, centre, height, width, knots):
        self.centre, self.height, self.width = np.asarray(centre), height, width
        self.knots = np.asarray(knots, dtype=np.float64)

    def evaluate(self, x):
        r2 = np.sum((x - self.centre) ** 2, axis=1) / self.width**2
        return np.c_[x, self.height * np.exp(-r2)]


def test_a_spike_in_the_gap_between_data_points_is_a_swing(monkeypatch):
    """A spike between data points that reaches none of their midpoints (the cliff of 5e4
    points dipped 43 m below points fitted within 0.9 m, 1-1.4 m away: user test) is found
    at the centroids of the data's Delaunay triangles (SWING_GAPS), and only there; the same
    spike over a data point is no swing (the error there shows it)."""
    g = np.arange(12.0)
    uv = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)  # a 1 m lattice, z = 0
    points = np.c_[uv, np.zeros(len(uv))]
    knots = np.array([[5.5, 5.5], [5.0, 5.0], [6.0, 6.0], [5.0, 6.0]])
    # 40 m high, 0.2 m wide at the centre of a cell: 10 m at the triangles' centroids (0.24 m
    # off), 0.08 m at the nearest midpoints (0.5 m off), 0 at the lattice points
    spike = _SpikedPlane([5.5, 5.5], 40.0, 0.2, knots)
    where, checked, largest = refine.swing_places(spike, np.eye(3), uv, points,
                                                  np.zeros(len(uv)))
    assert len(where) >= 1 and checked > 0 and largest > 5.0
    assert np.linalg.norm(where - [5.5, 5.5], axis=1).max() < 0.5
    monkeypatch.setattr(refine, "SWING_GAPS", False)
    assert len(refine.swing_places(spike, np.eye(3), uv, points, np.zeros(len(uv)))[0]) == 0
    monkeypatch.setattr(refine, "SWING_GAPS", True)
    # the same spike over a lattice point, whose error shows it, and the plane without it
    on_point = _SpikedPlane([5.0, 5.0], 40.0, 0.2, knots)
    errors = np.where(np.all(uv == 5.0, axis=1), 40.0, 0.0)
    assert len(refine.swing_places(on_point, np.eye(3), uv, points, errors)[0]) == 0
    flat = _SpikedPlane([5.5, 5.5], 0.0, 0.2, knots)
    assert len(refine.swing_places(flat, np.eye(3), uv, points, np.zeros(len(uv)))[0]) == 0


@pytest.mark.parametrize("threads", ["1", "2"])
def test_the_swing_checks_triangles_made_ahead_are_those_it_uses(monkeypatch, threads):
    """prefetch_swing_triangles starts the triangulation of the very sample swing_places takes
    (the final check of a fit, with the domain checks), so the check makes none of its own and
    finds what it finds without it; a sample of other points is triangulated anew."""
    monkeypatch.setenv("TCB_THREADS", threads)
    g = np.arange(12.0)
    uv = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    uv = uv + np.random.default_rng(1).uniform(-0.2, 0.2, uv.shape)
    points = np.c_[uv, np.zeros(len(uv))]
    spike = _SpikedPlane(uv[:4].mean(axis=0) + [0.1, 0.4], 40.0, 0.2, uv[[0, 1, 12, 13]])
    refine._GAP_CACHE.clear()
    plain = refine.swing_places(spike, np.eye(3), uv, points, np.zeros(len(uv)), seed=3,
                                domain=True)
    assert len(plain[0]) >= 1  # (the check finds something to compare)
    made = []
    triangulate = refine._triangulate
    monkeypatch.setattr(refine, "_triangulate", lambda x: made.append(len(x)) or triangulate(x))
    refine._GAP_CACHE.clear()
    refine.prefetch_swing_triangles(uv, seed=3)
    ahead = refine.swing_places(spike, np.eye(3), uv, points, np.zeros(len(uv)), seed=3,
                                domain=True)
    # the prefetched one, and no other of the sample (the points around knots that crowd
    # are triangulated on their own)
    assert made[0] == len(uv) and made.count(len(uv)) == 1
    assert np.array_equal(ahead[0], plain[0]) and ahead[1:] == plain[1:]
    # another sample is not taken for this one (with one thread, it is never made: nothing
    # asks for it)
    refine.prefetch_swing_triangles(uv + 1.0, seed=3)
    other = refine._GAP_CACHE["last"][1]
    again = refine.swing_places(spike, np.eye(3), uv, points, np.zeros(len(uv)), seed=3,
                                domain=True)
    if threads == "2":
        other()  # (wait for it)
    assert made.count(len(uv)) == (3 if threads == "2" else 2)
    assert np.array_equal(again[0], plain[0])


def test_a_cross_validated_smoothness_that_swings_off_the_data_is_raised(monkeypatch):
    """30 points of sin(3x): cross-validation chose 1e-5 and the surface swung 1.2 off the
    function between the points (its height range is 2; 1e-4 gives 0.23): held-out data
    points cannot see a swing in a gap between them (user test). A chosen smoothness whose
    surface swings (core.surface.data_swings) is replaced by the next larger candidate that
    does not; the selection says so. Where the choice does not swing, it stays.

    Since the points are fitted in an order of their coordinates, no cloud of 20-50 points of
    sin(kx), k = 3..6, seeds 0-9, gets a swinging choice (the user test's cloud now gets 1e-5,
    0.23 off inside its domain): the cross-validation is made to choose the least smoothing
    here, 1e-7, whose surface swings (0.52 off inside the domain at 2 places; 1e-6 too, 0.45),
    and 1e-5 (0.21) is taken."""
    def off(surf):  # inside the data's domain (beyond it the surface extrapolates)
        g = np.random.default_rng(9).random((5000, 2))
        uv = surf.parameterization.project(np.c_[g, np.sin(3 * g[:, 0])])
        S = surf(uv[surf.domain_contains(uv)])
        return np.abs(S[:, 2] - np.sin(3 * S[:, 0])).max()

    one_se = core.fit._one_standard_error
    monkeypatch.setattr(core.fit, "_one_standard_error",
                        lambda sq, w: (min(sq), one_se(sq, w)[1]))  # the least smoothing
    xy = np.random.default_rng(3).random((30, 2))
    P = np.c_[xy, np.sin(3 * xy[:, 0])]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # sparse data
        surf = fit_surface(P)
        chosen = fit_surface(P, smoothness=1e-7)
    sel = surf.report["smoothness_selection"]
    assert sel["chosen"] == 1e-7 and surf.report["smoothness"] == 1e-5
    assert "1e-07, the cross-validated choice, the surface swung away" in sel["smoother"]
    assert chosen.report["swings"]["places"] > 0 and surf.report["swings"]["places"] == 0
    assert off(surf) < 0.3 < 0.5 < off(chosen)
    monkeypatch.setattr(core.fit, "_one_standard_error", one_se)
    xy = np.random.default_rng(1).random((30, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        kept = fit_surface(np.c_[xy, np.sin(3 * xy[:, 0])])
    assert "smoother" not in kept.report["smoothness_selection"]
    assert kept.report["smoothness"] == kept.report["smoothness_selection"]["chosen"]


def test_the_loop_and_the_choice_agree_on_what_sparse_means():
    """400 points of two peaks for 201 control points: sparse for the loop (under 2 per control
    point) though not for a count of the functions that see data; the choice then also tries
    the larger candidates (it had tried 1e-2 ... 1e-7 only while the report said sparse)."""
    xy = np.random.default_rng(1).random((400, 2))
    z = np.exp(-20 * ((xy[:, 0] - 0.3) ** 2 + (xy[:, 1] - 0.3) ** 2)) - 0.5 * np.exp(
        -10 * ((xy[:, 0] - 0.7) ** 2 + (xy[:, 1] - 0.6) ** 2))
    sel = fit_surface(np.c_[xy, z]).report["smoothness_selection"]
    assert "sparse data: 400 points" in sel["why"]
    assert {"100", "10", "1", "0.1"} <= set(sel["cross_validated_rms"])


def test_a_tiny_cloud_keeps_the_cross_validated_smoothness_that_misses_the_tolerance():
    """12 points: the loop reaches the tolerance by (nearly) interpolating them; the smoother
    cross-validated surface misses it and is kept anyway (dense data would keep the loop's
    fit), and the stop reason says so."""
    xy = np.random.default_rng(1).random((12, 2))
    surf = fit_surface(np.c_[xy, franke(*xy.T)])
    r = surf.report
    assert r["smoothness"] == r["smoothness_selection"]["chosen"] >= 1.0
    assert "kept" not in r["smoothness_selection"] and r["rms_rel"] > 1e-3
    assert r["stop_reason"].startswith("tolerance reached by the loop") and "misses it" in r["stop_reason"]


def test_coarse_32_bit_coordinates_are_named_in_the_error_or_a_warning():
    """A unit patch at 1e6 in 32-bit floats is a 1/16 lattice: it was refused as a fold with
    no word about the real cause; at 1e4 the steps are 1e-3 of it: a warning says so."""
    import warnings

    xy = np.random.default_rng(0).random((2000, 2))
    patch = np.c_[xy, 0.3 * np.sin(3 * xy[:, 0])]
    with pytest.raises(InvalidInputError, match=r"32-bit floats, which far from the origin are 0\.0625"):
        fit_surface((patch + 1e6).astype(np.float32), max_control_points=200)
    with pytest.warns(RuntimeWarning, match=r"32-bit floats.*subtract an offset"):
        fit_surface((patch + 1e4).astype(np.float32), max_control_points=200)
    # 16-bit floats too (they had had no word: user test): 0.0625 apart at 64 to 70
    with pytest.warns(RuntimeWarning, match=r"16-bit floats, which far from the origin are "
                                            r"0\.0625 apart"):
        fit_surface((10 * patch + 60).astype(np.float16), max_control_points=200)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        fit_surface(patch.astype(np.float32), max_control_points=200)
        fit_surface(patch + 1e6, max_control_points=200)  # float64 at the same offset: fine


def test_refine_refuses_other_points_of_the_same_count(tmp_path):
    """Shuffled points or another scan of the same size gave garbage surfaces (relative RMS
    0.24) without an error; the digest kept in the report (also in files) refuses them, and a
    change of a point by 1e-4 of the diagonal. Points rounded again (float32 coordinates
    through another transform: Blender's Apply Rotation & Scale, user test) are the same data:
    each point's distance to the surface at its parameters stays its fitted error within 1e-6
    of the diagonal."""
    points = ridge_cloud(1500)
    surf = fit_surface(points, max_iterations=1, max_control_points=150)
    surf.save(tmp_path / "s.npz")
    loaded = TCBSurface.load(tmp_path / "s.npz")
    diagonal = surf.report["diagonal"]
    moved = points.copy()
    moved[700] += 1e-4 * diagonal
    rng = np.random.default_rng(2)
    rounded = points + rng.uniform(-1, 1, points.shape) * 2.0**-24 * np.abs(points).max()
    # (the same points in another order are taken: test_surface_api)
    others = [ridge_cloud(1500, 5), moved]
    for s in (surf, loaded):
        for other in others:
            assert not s.fitted_to(other)
            with pytest.raises(InvalidInputError, match="same order; these differ"):
                s.refine(other, max_iterations=1)
        assert s.fitted_to(points.copy()) and not s.fitted_to(points[:-1])
        assert s.refine(points.copy(),
                        max_iterations=1, max_control_points=200).report["iterations"] == 2
        assert s.fitted_to(rounded) and s.fitted_to(points + [0.0, 0.0, 1e-9])
        again = s.refine(rounded, max_iterations=1, max_control_points=200)
        assert again.fitted_to(rounded) and again.report["iterations"] == 2
        # an edited net (with_control_points) is compared as fitted, not as edited
        edited = s.with_control_points(s.control_points + [0.0, 0.0, 0.05])
        assert edited.fitted_to(rounded) and not edited.fitted_to(moved)
    # float32 rounding grows with the coordinates, not the cloud's size (review: a patch 1000
    # diagonals from the origin was refused): the caller passes what it rounded by (Blender:
    # 4 float32 steps of the largest coordinate)
    far = (points + 1000.0).astype(np.float32)
    surf = fit_surface(far.astype(np.float64), max_iterations=1, max_control_points=150)
    again = ((far * np.float32(3.0)) / np.float32(3.0)).astype(np.float64)
    steps = 4 * 2.0**-24 * np.abs(again).max()
    assert not np.array_equal(again, far.astype(np.float64))
    assert surf.fitted_to(again, rounding=steps)
    assert surf.refine(again, rounding=steps, max_iterations=1).report["iterations"] == 2
    # ... never guessed: float64 data at UTM northings (cm precision) shifted by 0.8 m had
    # passed, 4 float32 steps of 5e6 being 1.2 m (user test), and float32-valued data so
    # after a first fix (review)
    utm = np.round(points * 50 + [512345.67, 5123456.78, 250.0], 2)
    for data in (utm, utm.astype(np.float32).astype(np.float64)):
        surf = fit_surface(data, max_iterations=1, max_control_points=150)
        assert surf.fitted_to(data.copy()) and not surf.fitted_to(data + [0.8, 0.0, 0.0])
        assert not surf.fitted_to(data + [0.0, 0.0, 0.3])


def closed_octahedron():
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return v, f


def grid_mesh(n):
    """An n x n grid mesh of a smooth function over [-1, 1]^2 (triangles)."""
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    v = np.c_[x.ravel(), y.ravel(), 0.3 * np.sin(3 * x.ravel()) * np.cos(2 * y.ravel())]
    a = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    return v, np.vstack([np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]])


def test_a_list_of_triangles_and_quads_is_a_mesh():
    """A mesh's polygons in one list, triangles and quads mixed (numpy's "inhomogeneous
    shape" had been the answer: user test): each polygon is split (a quad along its shorter
    diagonal, core.geometry.quad_triangles), in the order of the polygons, so the fit is that
    of the same triangles; the indices are checked as one
    (1-based ones are named as such), and polygons of fewer than 3 vertices are named."""
    n = 12
    v, _ = grid_mesh(n)
    a = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    quads = np.c_[a, a + 1, a + n + 1, a + n]
    mixed = [list(q) for q in quads[:40]] + [list(t) for q in quads[40:]
                                             for t in (q[[0, 1, 2]], q[[0, 2, 3]])]
    mixed[3], mixed[50] = mixed[50], mixed[3]  # (a triangle among the quads)
    tris = np.vstack([quad_triangles(v, np.array([q])) if len(q) == 4 else [q]
                      for q in mixed])
    surf = fit_surface(v, mixed, tolerance=1e-2)
    ref = fit_surface(v, tris, tolerance=1e-2)
    assert np.array_equal(surf.parameterization.faces, ref.parameterization.faces)
    assert np.array_equal(surf.control_points, ref.control_points)
    assert surf.report["rms_rel"] < 1e-2
    with pytest.raises(InvalidInputError, match=r"out of range .*numbered from 1"):
        fit_surface(v, [[i + 1 for i in q] for q in mixed])
    with pytest.raises(InvalidInputError, match=r"1 of the 203 faces have fewer than 3 "
                                                r"vertices \(the first: face 7, \[1, 2\]\)"):
        fit_surface(v, mixed[:7] + [[1, 2]] + mixed[7:])


def test_small_integer_faces_below_their_limit_are_a_mesh():
    """uint8 faces whose indices stay below 255, with more (unused) vertices than 255 after
    them: a mesh (review; only faces that reach the type's limit may have wrapped round)."""
    v, f = grid_mesh(12)
    extra = np.random.default_rng(0).random((200, 3))
    with pytest.warns(RuntimeWarning, match="in no face"):
        surf = fit_surface(np.vstack([v, extra]), f.astype(np.uint8), tolerance=1e-2)
    assert surf.parameterization.used.sum() == len(v)


def grid_with_hole(n=6):
    g = np.arange(n, dtype=float)
    v = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    v = np.c_[v, 0.1 * np.sin(v[:, 0])]
    faces = []
    for j in range(n - 1):
        for i in range(n - 1):
            if (i, j) == (2, 2):
                continue  # the hole
            a = j * n + i
            faces += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return v, np.array(faces)


def test_fill_holes_spans_a_mesh_s_holes_and_keeps_its_own_vertices_and_faces(tmp_path, monkeypatch):
    """A 31 x 31 grid mesh of a smooth function with two holes (the faces near two centres
    removed, their inner vertices left loose): refused with a HolesError that names
    fill_holes; with it the surface meets the tolerance at the vertices, spans the holes
    within 1% of the function's range there, and the parameterization keeps the mesh's own
    vertices and faces (no fan vertex or face left), counting each hole's border. A C-shaped
    hole, which a fan from its centre would squeeze, is closed by ears of its border and fits
    as a disk does; a hole no triangulation closes is refused with advice. A tube's second
    loop is no hole."""
    from core import HolesError

    m = 31
    g = np.linspace(0, 1, m)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    f = lambda x, y: 0.3 * np.sin(3 * x) * np.cos(2 * y)  # noqa: E731
    P = np.c_[x, y, f(x, y)]
    i = np.arange(m * m).reshape(m, m)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    F = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    cen = P[F].mean(axis=1)
    F = F[(np.hypot(cen[:, 0] - 0.5, cen[:, 1] - 0.45) > 0.12)
          & (np.hypot(cen[:, 0] - 0.2, cen[:, 1] - 0.75) > 0.07)]
    with pytest.raises(HolesError, match=r"3 boundary loops .*\(fill_holes=True\)"):
        fit_surface(P, F)
    # coarse float32 coordinates add a note; the error keeps its fields (review: loops was 2)
    with pytest.raises(HolesError, match=r"3 boundary loops .*\(note: .*32") as info:
        fit_surface((P * 100 + 1e6).astype(np.float32), F)
    assert info.value.loops == 3
    with pytest.warns(RuntimeWarning, match="vertices are in no face"):
        surf = fit_surface(P, F, fill_holes=True)
    par = surf.parameterization
    assert surf.report["holes_filled"] == 2 and surf.report["rms_rel"] <= 1e-3
    assert par.uv.shape == (len(P), 2) and np.array_equal(par.used, np.isin(np.arange(len(P)), F))
    assert len(par.faces) == len(F) and par.faces.max() < len(P)
    np.testing.assert_array_equal(np.sort(np.sort(par.faces, axis=1), axis=0),
                                  np.sort(np.sort(F, axis=1), axis=0))
    # each hole's border: the vertices of edges in one face, away from the grid's border
    e = np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    border = np.unique(edges[count == 1])
    inner = border[(x[border] > 0) & (x[border] < 1) & (y[border] > 0) & (y[border] < 1)]
    near_first = np.hypot(x[inner] - 0.5, y[inner] - 0.45) < 0.25
    assert sorted(par.holes) == sorted([int(near_first.sum()), int((~near_first).sum())])
    assert np.all(orient2d(*(par.uv[par.faces[:, k]] for k in range(3))) > 0)
    for cx, cy, r in ((0.5, 0.45, 0.08), (0.2, 0.75, 0.04)):
        t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
        q = np.c_[cx + r * np.cos(t), cy + r * np.sin(t)]
        near = surf.closest_points(np.c_[q, f(*q.T)])
        assert np.abs(near[:, 2] - f(near[:, 0], near[:, 1])).max() < 0.01 * 0.6
    V, _ = surf.tessellate(64)
    assert np.count_nonzero(np.hypot(V[:, 0] - 0.5, V[:, 1] - 0.45) < 0.08) > 10  # spanned
    back = TCBSurface.from_bytes(surf.to_bytes(compact=True))
    np.testing.assert_array_equal(back.parameterization.holes, par.holes)
    with pytest.warns(RuntimeWarning, match="vertices are in no face"):
        assert len(back.refine(P, F, max_iterations=1).control_points) > 0
    # a tube: its two ends are equally long, no hole of one another
    t = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t)]
    tube = np.vstack([np.c_[ring, np.full(24, z)] for z in np.linspace(0, 2, 8)])
    k = np.arange(24)
    quads = [(r * 24 + k, r * 24 + (k + 1) % 24, (r + 1) * 24 + (k + 1) % 24, (r + 1) * 24 + k)
             for r in range(7)]
    tf = np.vstack([np.r_[np.c_[q0, q1, q2], np.c_[q0, q2, q3]] for q0, q1, q2, q3 in quads])
    for fill in (True, False):  # (without the option too: it would not help; review)
        with pytest.raises(TopologyError, match="1.00 times the size of the largest, too "
                           "large for a hole to be spanned .the two ends of a tube") as info:
            fit_surface(tube, tf, fill_holes=fill)
        assert "fill_holes" not in str(info.value)
    # a C-shaped hole: its centre does not see its border, a fan would squeeze the map (max
    # error 0.073 of the diagonal, 326 control points, 0.012 off the function in the hole):
    # its border is clipped into ears instead, and it fits as a disk of its size does (147
    # control points, max 8.8e-4; measured: 141, 7.1e-4, 9.1e-4 off in the hole; since a
    # start that meets the tolerance by far is followed by coarser ones: 76, 1.7e-3)
    cells = np.c_[a, b, c, d]
    r, q = np.divmod(np.arange(len(cells)), m - 1)
    ring = np.hypot(r - 14.5, q - 14.5)
    cut = (ring >= 3.5) & (ring <= 5.0) & ~((q > 14.5) & (np.abs(r - 14.5) < 2))
    with pytest.warns(RuntimeWarning, match="vertices are in no face"):
        c_surf = fit_surface(P, cells[~cut], fill_holes=True)
    assert c_surf.report["holes_filled"] == 1 and c_surf.report["control_points"] <= 170
    assert c_surf.report["max_rel"] < 3e-3
    kept = cells[~cut]
    c_par = c_surf.parameterization
    np.testing.assert_array_equal(np.sort(np.sort(c_par.faces, axis=1), axis=0),
                                  np.sort(np.sort(quad_triangles(P, kept), axis=1), axis=0))
    assert np.all(orient2d(*(c_par.uv[c_par.faces[:, k]] for k in range(3))) > 0)
    cen = np.c_[(q[cut] + 0.5) / (m - 1), (r[cut] + 0.5) / (m - 1)]
    near = c_surf.closest_points(np.c_[cen, f(*cen.T)])
    assert np.abs(near[:, 2] - f(near[:, 0], near[:, 1])).max() < 0.003 * 0.6
    # a hole no triangulation of its border closes (here: the border polygon taken to cross
    # itself in every plane, as rounding could make it) is refused with advice, not squeezed
    import core.parameterize as parameterize_module

    monkeypatch.setattr(parameterize_module, "simple_polygon", lambda xy: False)
    with pytest.raises(ParameterizationError, match=r"1 of the mesh's 1 holes cannot be spanned "
                       r".* winds .* Grid Fill"):
        fit_surface(P, cells[~cut], fill_holes=True)
    monkeypatch.undo()
    with pytest.raises(InvalidInputError, match="fill_holes must be True or False"):
        fit_surface(P, F, fill_holes="yes")


def _covered(uv, tri, x):
    """Mask of the parameters ``x`` inside one of the triangles ``tri`` of ``uv``."""
    a, b, c = (uv[tri[:, k]][None] for k in range(3))
    p = x[:, None]
    s = np.sign(orient2d(a, b, c))
    inside = ((np.sign(orient2d(a, b, p)) * s >= 0) & (np.sign(orient2d(b, c, p)) * s >= 0)
              & (np.sign(orient2d(c, a, p)) * s >= 0))
    return inside.any(axis=1)


def test_fill_holes_covers_a_cloud_s_holes_but_not_its_bays(tmp_path):
    """A scan with two occlusions (round gaps inside the cloud) and a notch cut into its side:
    the tessellation leaves all three open; with fill_holes the same fit (the option changes
    where the surface is shown, not the fit) covers the two holes, within a few fit errors of
    the shape there, and leaves the notch, which reaches the cloud's outline, open; the report
    counts the holes, the parameterization finds them (in_holes), a stored surface
    tessellates as the fitted one and a refine of the points in another order covers them.
    A ring's middle is too large to be a hole: left open with a warning."""
    f = lambda x, y: 0.3 * np.sin(2 * x) * np.cos(1.5 * y) + 0.1 * x * y  # noqa: E731
    xy = np.random.default_rng(3).uniform(-1, 1, (12000, 2))
    holes = np.array([[-0.4, 0.3], [0.3, -0.35]]), np.array([0.15, 0.25])
    keep = (np.hypot(*(xy[:, None] - holes[0]).transpose(2, 0, 1)) > holes[1]).all(axis=1)
    keep &= ~((xy[:, 0] > 0.5) & (np.abs(xy[:, 1] - 0.4) < 0.15))  # the notch
    P = np.c_[xy[keep], f(*xy[keep].T)]
    plain = fit_surface(P, tolerance=2e-3)
    filled = fit_surface(P, tolerance=2e-3, fill_holes=True)
    assert np.array_equal(plain.control_points, filled.control_points)
    assert plain.report["holes_filled"] == 0 and filled.report["holes_filled"] == 2
    # (what the command line and Blender say without the option: the gaps left open)
    assert plain.open_holes(128) == 2 and filled.open_holes(128) == 0
    par = filled.parameterization
    spots = par.project(np.c_[np.r_[holes[0], [[0.85, 0.4]]], np.zeros(3)])  # holes, notch
    assert list(par.in_holes(spots)) == [True, True, False]
    assert not par.in_holes(par.uv).any() and not plain.parameterization.in_holes(spots).any()
    for surf, covered in ((plain, [False, False, False]), (filled, [True, True, False])):
        uv, tri = surf.tessellation_uv(128)
        assert list(_covered(uv, tri, spots)) == covered
    # over the holes the surface keeps to the shape (held by the fairing: no data there)
    v, _ = filled.tessellate(128)
    over = par.in_holes(filled.tessellation_uv(128)[0])
    assert over.sum() > 100
    off = np.abs(v[over, 2] - f(v[over, 0], v[over, 1]))
    assert off.max() < 10 * filled.report["rms"], (off.max(), filled.report["rms"])
    filled.save(tmp_path / "s.npz")
    again = TCBSurface.load(tmp_path / "s.npz")
    assert np.array_equal(again.tessellation_uv(128)[1], filled.tessellation_uv(128)[1])
    turned = again.refine(P[::-1], max_iterations=1)
    assert turned.report["holes_filled"] == 2
    assert list(_covered(*turned.tessellation_uv(128), spots)) == [True, True, False]
    # a ring's middle (a box 0.6 of the square's diagonal) is not a hole: left open, said so
    ring = xy[np.hypot(*xy.T) > 0.6]
    with pytest.warns(RuntimeWarning, match=r"a gap inside the point cloud 0\.[56]\d times its "
                      r"size across .* is left open"):
        ringed = fit_surface(np.c_[ring, f(*ring.T)], fill_holes=True, max_iterations=1)
    assert ringed.report["holes_filled"] == 0
    middle = ringed.parameterization.project(np.zeros((1, 3)))
    assert not _covered(*ringed.tessellation_uv(128), middle)[0]


def test_a_slot_that_winds_around_a_bend_is_closed_in_the_map_of_its_fan(monkeypatch):
    """A strip bent by 240 degrees with a slot along the bend: seen across the slot (the
    plane of its vector area) its border crosses itself, so its ears are clipped in the map
    of the mesh with the slot closed by a fan (an embedding). The map keeps the mesh's own
    faces unfolded, and the fit misses the vertices by less than 1% of the diagonal (measured
    7.2e-3; with the fan alone 0.012, the whole strip 0.015)."""
    import core.parameterize as parameterize_module

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        from holes import bent_strip  # (the benchmark's strip)
    finally:
        sys.path.pop(0)
    P, F, lost = bent_strip(240, ns=61, nz=11)
    simple = []
    real = parameterize_module.simple_polygon
    monkeypatch.setattr(parameterize_module, "simple_polygon",
                        lambda xy: simple.append(real(xy)) or simple[-1])
    with pytest.warns(RuntimeWarning, match="vertices are in no face"):
        surf = fit_surface(P, F, fill_holes=True)
    # across the slot, then in the fans' map (then the flattened boundary's checks, a
    # simple polygon each time)
    assert simple[:2] == [False, True] and all(simple[2:])
    par = surf.parameterization
    assert len(par.faces) == 2 * len(F) and par.faces.max() < len(P) and len(lost) == 13
    assert np.all(orient2d(*(par.uv[par.faces[:, k]] for k in range(3))) > 0)
    assert surf.report["holes_filled"] == 1 and surf.report["max_rel"] < 0.01


def test_a_slot_whose_fan_bulges_away_along_a_bend_is_clipped(monkeypatch):
    """A strip bent by 90 degrees with a slot along the bend: the slot's fan faces backwards
    nowhere, but it tents away from the strip (its centre lies inside the bend); its border,
    clipped, spans the slot with less than HOLE_BULGE of the fan's area, so it is clipped.
    Measured: max error 2.1e-3 of the diagonal clipped, 6.0e-3 with the fan; now 1.6e-3 and
    6.8e-3, both from the probe's start (the coarser starts after a start that meets the
    tolerance by far made nets of different sizes: 4.1e-3 against 6.8e-3)."""
    import core.parameterize as parameterize_module

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        from holes import bent_strip  # (the benchmark's strip)
    finally:
        sys.path.pop(0)
    P, F, lost = bent_strip(90, ns=61, nz=11)
    errors = {}
    for rule, bulge in (("fan", 0.0), ("shipped", parameterize_module.HOLE_BULGE)):
        monkeypatch.setattr(parameterize_module, "HOLE_BULGE", bulge)
        with pytest.warns(RuntimeWarning, match="vertices are in no face"):
            surf = fit_surface(P, F, fill_holes=True,
                               initial_knots=automatic_start("tcb", 2000) // 4)
        par = surf.parameterization
        assert len(par.faces) == 2 * len(F) and surf.report["holes_filled"] == 1
        assert np.all(orient2d(*(par.uv[par.faces[:, k]] for k in range(3))) > 0)
        errors[rule] = surf.report["max_rel"]
    # (with no bulge allowed the fan is kept: it faces backwards by less than HOLE_BACKWARD)
    assert errors["shipped"] < 3e-3 and errors["fan"] > 2 * errors["shipped"], errors


@pytest.mark.parametrize(
    "case, error, words",
    [
        ("nan", InvalidInputError, "NaN"),
        ("inf", InvalidInputError, "inf"),
        ("few", InvalidInputError, "at least 10"),
        ("identical", InvalidInputError, "identical"),
        ("collinear", InvalidInputError, "line"),
        ("duplicates", InvalidInputError, "distinct"),
        ("closed", TopologyError, "closed"),
        ("hole", TopologyError, "boundary loops"),
        ("shape", InvalidInputError, r"\(N, 3\)"),
        ("complex", InvalidInputError, "real numbers, got complex"),  # (dropped: user test)
        ("far", InvalidInputError, "where 64-bit coordinates are 0.125 apart"),  # (user test)
        # a raster's no-data cells, and masked values (fitted as terrain: user test)
        ("fill", InvalidInputError, r"20 of the 200 points have z = -9999, far below all "
                                    r"others \(lowest 0.0.*\): a no-data fill value.*"
                                    r"points\[points\[:, 2\] != -9999\]"),
        ("mesh fill", InvalidInputError, r"3 of the 36 vertices in faces have z = -32768, "
                                         r"far below .*; repair those vertices or cut them out"),
        ("loose fill", TopologyError, "boundary loops"),  # (a loose vertex is left out)
        # float32's largest value (Blender's stored infinity), above the data: the map had
        # failed as "triangles came out flipped or degenerate" (user test)
        ("huge", InvalidInputError, r"1 of the 200 points has coordinates of 1e30 or more in "
                                    r"size \(the first: #7, \(.*, 3\.403e\+38\)\): float32's "
                                    r"largest value .*; leave those rows out"),
        ("mesh huge", InvalidInputError, r"1 of the 36 vertices in faces has coordinates of 1e30 "
                                         r"or more in size \(the first: #4, .*repair those"),
        ("masked", InvalidInputError, r"3 of the points are masked.*points\[~points.mask.any"),
        # (refused as non-manifold edges: user test)
        ("transposed faces", InvalidInputError, r"got shape \(3, 48\), 3 polygons of 48 "
                                                r"vertices: transposed\? pass faces.T"),
        # (said "out of range; fix the face list", "non-manifold edges" and "split or remove
        # the faces there": user test)
        ("1-based faces", InvalidInputError, r"out of range .*numbered from 1 .*pass faces - 1"),
        ("uint8 faces", InvalidInputError, r"the faces are uint8 integers, which hold indices "
                                           r"up to 255, and reach it, but the mesh has 400 "
                                           r"vertices"),
        ("duplicated vertex", TopologyError, r"2 non-manifold vertices .*Merge by Distance\): "
                                             r"vertices there are duplicated"),
    ],
)
def test_bad_input_raises_a_specific_error(case, error, words):
    rng = np.random.default_rng(0)
    faces = None
    points = rng.random((200, 3))
    if case == "nan":
        points[5, 1] = np.nan
    elif case == "inf":
        points[7, 2] = np.inf
    elif case == "few":
        points = points[:9]
    elif case == "identical":
        points = np.ones((50, 3))
    elif case == "collinear":
        points = np.outer(np.linspace(0, 1, 50), [1.0, 2.0, 3.0])
    elif case == "duplicates":
        points = np.repeat(rng.random((5, 3)), 20, axis=0)
    elif case == "closed":
        points, faces = closed_octahedron()
    elif case == "hole":
        points, faces = grid_with_hole()
    elif case == "shape":
        points = rng.random((50, 2))
    elif case == "complex":
        points = points + 1j
    elif case == "far":
        points = points + 1e15  # ("more auxiliary border rings are needed" had been said)
    elif case == "fill":
        points[rng.choice(200, 20, replace=False), 2] = -9999.0
    elif case == "mesh fill":
        points, faces = grid_with_hole()
        points = np.array(points, dtype=np.float64)
        points[:3, 2] = -32768.0
    elif case == "loose fill":
        points, faces = grid_with_hole()
        points = np.vstack([points, [0.0, 0.0, -9999.0]])
    elif case == "huge":
        points[7, 2] = float(np.finfo(np.float32).max)
    elif case == "mesh huge":
        points, faces = grid_with_hole()
        points[4, 0] = -3e38
    elif case == "transposed faces":
        points, faces = grid_with_hole(6)
        faces = faces.T
    elif case == "1-based faces":
        points, faces = grid_with_hole(6)
        faces = faces + 1
    elif case == "uint8 faces":
        points, faces = grid_mesh(20)
        faces = faces.astype(np.uint8)
    elif case == "duplicated vertex":  # an interior vertex copied, 3 of its faces on the copy
        points, faces = grid_mesh(8)
        v = 8 * 4 + 4
        points = np.vstack([points, points[v]])
        fan = np.flatnonzero((faces == v).any(axis=1))[:3]
        part = faces[fan]
        part[part == v] = len(points) - 1
        faces[fan] = part
    elif case == "masked":
        mask = np.zeros(points.shape, dtype=bool)
        mask[[3, 8, 9], 2] = True
        points = np.ma.masked_array(points, mask=mask)
    with pytest.raises(error, match=words) as info:
        fit_surface(points, faces)
    assert isinstance(info.value, (TCBError, ValueError))


@pytest.mark.parametrize(
    "options, words",
    [
        ({"tolerance": "1e-3"}, "tolerance must be a nonnegative number, got '1e-3'"),
        ({"tolerance": None}, "tolerance must be a nonnegative number, got None"),
        ({"max_control_points": np.inf}, "max_control_points must be a whole number"),
        ({"max_control_points": np.nan}, "max_control_points must be a whole number"),
        ({"max_control_points": None}, "max_control_points must be a whole number"),
        ({"max_control_points": 400.5}, "max_control_points .* got 400.5"),
        ({"max_iterations": 2.5}, "max_iterations must be a whole number"),
        ({"degree": "2"}, "degree must be 2 or 3, got '2'"),
        ({"degree": 2.5}, "degree must be 2 or 3, got 2.5"),
        ({"initial_knots": -5}, "initial_knots must be .* at least 1, or None .*got -5"),
        ({"initial_knots": 0}, "initial_knots .* or None for the automatic"),
        ({"knots_per_iteration": 1.5}, "knots_per_iteration must be a whole number"),
        ({"knots_per_iteration": -3}, "knots_per_iteration .* got -3"),
        ({"seed": -1}, "seed must be a nonnegative whole number, got -1"),
        ({"seed": "a"}, "seed must be a nonnegative whole number, got 'a'"),
        ({"relative": "no"}, "relative must be True or False, got 'no'"),
        ({"feature_sensitive": 0.5}, "feature_sensitive must be True or False"),
        ({"mode": "tcbx"}, "mode must be 'tcb' or 'dcb' \\(any case\\), got 'tcbx'"),
        ({"criterion": "mean"}, "criterion must be 'rms' or 'max'"),
        ({"callback": 5}, "callback must be a function"),
        ({"callback": lambda: None}, "callback must take one argument"),  # (after a fit: user test)
    ],
)
def test_bad_options_raise_a_specific_error_before_the_fit(options, words):
    points = ridge_cloud(300)
    with pytest.raises(InvalidInputError, match=words):
        fit_surface(points, **options)
    if "callback" not in options:  # refine() checks its changes the same way
        surf = fit_surface(points, max_iterations=1, max_control_points=100)
        with pytest.raises(InvalidInputError, match=words):
            surf.refine(points, **options)


def test_option_spellings_that_mean_a_valid_setting_are_accepted_and_stored_plainly(tmp_path):
    """2.0, numpy integers and bools, upper-case words: the same fit as the plain spelling,
    options stored as plain Python values (a file keeps them)."""
    points = ridge_cloud(300)
    plain = fit_surface(points, max_iterations=2, max_control_points=100, seed=1)
    odd = fit_surface(points, degree=2.0, mode=" TCB", criterion="RMS", relative=np.bool_(True),
                      max_iterations=np.int64(2), max_control_points=100.0, seed=np.int32(1),
                      tolerance=np.float32(1e-3))
    np.testing.assert_array_equal(plain.coefficients, odd.coefficients)
    assert odd.options.degree == 2 and type(odd.options.degree) is int
    assert odd.options.mode == "tcb" and odd.options.criterion == "rms"
    assert odd.options.relative is True and type(odd.options.seed) is int
    odd.save(tmp_path / "odd.npz")
    assert TCBSurface.load(tmp_path / "odd.npz").options == odd.options


def test_refine_names_the_options_it_knows():
    points = ridge_cloud(300)
    surf = fit_surface(points, max_iterations=1, max_control_points=100)
    with pytest.raises(InvalidInputError, match="no option 'foo'.*max_control_points"):
        surf.refine(points, foo=1)


def test_a_callback_must_return_a_bool_or_none():
    points = ridge_cloud(300)
    with pytest.raises(InvalidInputError, match="callback must return None or False"):
        fit_surface(points, max_iterations=2, callback=lambda report: np.array([1, 2]))
    seen = []
    # 300 points are a sparse cloud: a cancelled run is not cross-validated, and says so (the
    # third fit has 174 control points, under 2 points each; the second's 153 are not sparse)
    with pytest.warns(RuntimeWarning, match="cancelled before the smoothness was cross-validated"):
        surf = fit_surface(points, max_iterations=4, tolerance=0,
                           callback=lambda report: seen.append(report) or np.bool_(len(seen) == 3))
    assert surf.report["stop_reason"] == "cancelled" and len(seen) == 3
    # a smoothness given is never cross-validated: the warning does not say it would have been
    with pytest.warns(RuntimeWarning, match="make it 'auto'") as got:
        fit_surface(points, max_iterations=3, tolerance=0, smoothness=1e-4,
                    callback=lambda r: r["iteration"] == 2)
    assert not any("cancelled before" in str(w.message) for w in got)


def test_huge_inputs_are_fitted_on_a_subset_with_a_warning(monkeypatch):
    import core.surface

    monkeypatch.setattr(core.surface, "MAX_FIT_POINTS", 3000)
    xy = np.random.default_rng(0).random((10000, 2))
    points = np.c_[xy, np.sin(3 * xy[:, 0]) * xy[:, 1]]
    with pytest.warns(RuntimeWarning, match="random subset of 3000"):
        surf = fit_surface(points, max_iterations=2)
    assert surf.report["subsampled"] and surf.report["points"] == 10000
    # the errors are those of every input point, not only of the fitted subset
    true = np.linalg.norm(surf(surf.parameterization.uv) - points, axis=1)
    np.testing.assert_allclose(surf.errors, true, rtol=1e-9, atol=1e-12)
    assert surf.report["rms"] == pytest.approx(np.sqrt(np.mean(true**2)), rel=1e-9)


def test_large_inputs_iterate_on_a_subset_and_fit_the_chosen_knots_to_all_points(monkeypatch):
    """Above ITERATION_POINTS the iterations fit a random subset; the chosen space is then
    fitted to every point: the result is exactly the least-squares fit of that space to all
    points, and the reported errors are those of all points."""
    import core.refine

    monkeypatch.setattr(core.refine, "ITERATION_POINTS", 4000)
    xy = np.random.default_rng(1).random((12000, 2))
    points = np.c_[xy, 0.25 * np.abs(xy[:, 1] - 0.4 - 0.1 * np.sin(5 * xy[:, 0]))]
    surf = fit_surface(points, tolerance=0.0, max_control_points=400, max_iterations=4)
    hist = surf.report["history"]
    assert len(hist) == 4 and all(h["sampled_points"] == 4000 for h in hist)
    assert surf.report["refit"]["points"] == 12000
    true = np.linalg.norm(surf(surf.parameterization.uv) - points, axis=1)
    np.testing.assert_allclose(surf.errors, true, rtol=1e-9, atol=1e-12)
    assert surf.report["rms"] == pytest.approx(np.sqrt(np.mean(true**2)), rel=1e-9)
    best = min(hist, key=lambda h: h["rms"])  # the chosen iteration
    assert surf.report["control_points"] == best["control_points"]
    from core.parameterize import normalize

    q, norm = normalize(points)  # the fit works in normalized coordinates
    direct = fit_control_points(surf.space, surf.parameterization.uv, q, smoothness=1e-4)
    np.testing.assert_allclose(surf.coefficients, norm.undo(direct.control_points), rtol=0,
                               atol=1e-12)
    # the subset's RMS estimates the full one
    assert surf.report["rms"] == pytest.approx(best["rms"], rel=0.15)
    # the max criterion is never sampled (a subset cannot bound the largest error)
    smax = fit_surface(points, tolerance=0.0, criterion="max", max_control_points=300,
                       max_iterations=2)
    assert "refit" not in smax.report
    assert all("sampled_points" not in h for h in smax.report["history"])


def test_large_meshes_iterate_on_a_subset_with_the_vertices_measured(monkeypatch):
    """A mesh is fitted to its vertices plus samples on its faces; with the iterations on a
    subset, the tolerance and reports still measure only the vertices."""
    import core.refine

    monkeypatch.setattr(core.refine, "ITERATION_POINTS", 3000)
    n = 30
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    keep = (u**2 + v**2 <= 1).ravel()
    uv = np.c_[u.ravel(), v.ravel()][keep]
    from scipy.spatial import Delaunay

    faces = Delaunay(uv).simplices
    points = np.c_[uv, 0.3 * np.sin(2 * uv[:, 0]) * uv[:, 1]]
    surf = fit_surface(points, faces, tolerance=0.0, max_control_points=300, max_iterations=3)
    assert surf.report["refit"]["points"] > 3000  # vertices and face samples
    assert all(h["sampled_points"] == 3000 for h in surf.report["history"])
    used = surf.parameterization.used
    assert surf.report["rms"] == pytest.approx(np.sqrt(np.mean(surf.errors[used] ** 2)), rel=1e-12)
    assert surf.report["rms_rel"] < 1e-2


def test_knot_insertion_at_knots_on_knot_lines_and_at_the_border_stays_c1_and_sums_to_one():
    """Errors concentrated exactly on knots, on knot lines and at the border of the data must
    not make collinear configurations or break the partition of unity (issue 6, item 5)."""
    from itertools import combinations

    from core.border import border_rings, default_ring_count
    from core.refine import insertion_points, make_space

    rng = np.random.default_rng(3)
    inner = rng.random((40, 2))
    rings = border_rings([0, 0], [1, 1], 1 / np.sqrt(40), rings=default_ring_count(2), seed=3)
    knots = np.vstack([inner, rings])
    space = make_space(knots, 2, "tcb", None, len(inner))
    tri = space.configurations.triangles[0]
    # data exactly on the interior knots, on the midpoints of Gamma_0 edges, and on the border
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    mids = knots[edges].mean(axis=1)
    border = np.c_[rng.random(200), rng.choice([0.0, 1.0], 200)]
    uv = np.vstack([inner, mids, border, rng.random((3000, 2))])
    uv = uv[((uv >= 0) & (uv <= 1)).all(axis=1)]
    errors = np.zeros(len(uv))
    errors[: len(uv) - 3000] = 1.0  # all the error sits on knots, knot lines and the border
    for _ in range(3):
        new = insertion_points(knots, tri, uv, errors, count=25)
        assert len(new) > 0
        inner = np.vstack([inner, new])
        knots = np.vstack([inner, rings])
        space = make_space(knots, 2, "tcb", None, len(inner))
        tri = space.configurations.triangles[0]
        assert space.check_partition_of_unity(uv, tol=1e-9).ok
        V = knots[np.concatenate([space.config_triangles, space.config_interior], axis=1)]
        worst = np.inf
        for i, j, k in combinations(range(V.shape[1]), 3):
            a, b, c = V[:, i], V[:, j], V[:, k]
            det = np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
            L2 = np.maximum.reduce([((b - a) ** 2).sum(1), ((c - a) ** 2).sum(1), ((c - b) ** 2).sum(1)])
            worst = min(worst, float((det / L2).min()))
        assert worst > 1e-4  # no three (nearly) collinear knots in any configuration


def test_a_new_knot_never_lands_on_a_data_point():
    """Where one data point carries all of a triangle's error (exact data: a narrow ridge 8 m
    high, 1.5 m wide, in a 200 m tile of 2e4 points) the error-weighted centroid is that
    point; a knot there (3.5e-18 off in the parameters) broke the partition of unity at it,
    and the fit stopped with a BorderError after 13 iterations. The knot now goes a hundredth
    of the way to the triangle's centre."""
    from scipy.spatial import cKDTree

    from core.border import border_rings, default_ring_count
    from core.refine import insertion_points, make_space

    rng = np.random.default_rng(5)
    inner = rng.random((30, 2))
    rings = border_rings([0, 0], [1, 1], 1 / np.sqrt(30), rings=default_ring_count(2), seed=5)
    knots = np.vstack([inner, rings])
    tri = make_space(knots, 2, "tcb", None, len(inner)).configurations.triangles[0]
    uv = rng.random((3000, 2))
    errors = np.zeros(len(uv))
    errors[rng.choice(len(uv), 20, replace=False)] = 1.0  # one point per triangle, exactly
    new = insertion_points(knots, tri, uv, errors, count=20, min_points=1)
    assert len(new) > 0
    assert cKDTree(uv).query(new)[0].min() > 1e-6
    # the ridge itself fits (it raised BorderError)
    xy = np.random.default_rng(7).random((20_000, 2)) * 200
    z = (5 * np.sin(xy[:, 0] / 40) + 3 * np.cos(xy[:, 1] / 30)
         + 8 * np.exp(-(((xy[:, 0] - 100) / 1.5) ** 2)))
    surf = fit_surface(np.c_[xy, z], tolerance=0.05, relative=False, projection="z")
    assert surf.report["rms"] < 0.1


def test_distances_recover_known_offsets_along_the_normal():
    """Points moved by t along the unit normal are at distance |t| with closest parameters
    where they started (t small against the curvature radius), for a cloud and a mesh."""
    xy = np.random.default_rng(3).random((4000, 2))
    cloud = fit_surface(np.c_[xy, franke(*xy.T)], max_control_points=300)
    points, faces = read_geometry(DATA / "nefertiti.off")
    mesh = fit_surface(points, faces, max_control_points=300)
    for surf in (cloud, mesh):
        uv, _ = surf.tessellation_uv(40)
        uv = uv[np.abs(uv).max(axis=1) < 0.6 * np.abs(uv).max()]  # away from the domain's edge
        t = np.random.default_rng(4).uniform(-1, 1, len(uv)) * 1e-3 * surf.report["diagonal"]
        p = surf(uv) + t[:, None] * surf.normals(uv)
        np.testing.assert_allclose(surf.distances(p), np.abs(t), rtol=0,
                                   atol=1e-6 * surf.report["diagonal"])
        np.testing.assert_allclose(surf.closest_parameters(p), uv, rtol=0, atol=1e-5)


def test_a_wiggly_fit_s_own_tessellation_lies_on_it_and_offsets_measure_their_length(monkeypatch):
    """A coarse creased mesh (a 6 x 7 quad grid of random heights) fitted with about 600
    control points folds at its creases within a step of the starting tessellation: from the
    nearest start alone, its own tessellation's vertices measured up to 4.7e-3 of the diagonal
    from the surface at resolution 256 (4.0e-3 at 64; user test: 4.4e-3 and 9.2e-3 on a
    Suzanne patch of 42 vertices and 642 control points). With the other starts on the point's
    side of the tangent plane (TCBSurface._other_starts) they measure ~2e-8 of the diagonal,
    and points moved 1e-3 of it along the normal measure that, or less where another part of
    the surface is closer (a fold: never more). (Its random heights measure as noise: the net
    of a noisy mesh is capped at one control point per vertex, refine.NOISY_NET_PER_VERTEX,
    which is lifted here for the wiggly net this is about.)"""
    monkeypatch.setattr(refine, "NOISY_NET_PER_VERTEX", np.inf)
    rng = np.random.default_rng(2)
    x, y = np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1.2, 7))
    points = np.c_[x.ravel(), y.ravel(), 0.5 * rng.random(42)]
    points[:, :2] += 0.05 * rng.standard_normal((42, 2))
    i, j = np.meshgrid(np.arange(5), np.arange(6))
    a = (j * 6 + i).ravel()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (a coarse mesh, many control points)
        surf = fit_surface(points, np.c_[a, a + 1, a + 7, a + 6], tolerance=1e-4,
                           max_control_points=700)
    assert len(surf.control_points) > 500
    diag = surf.report["diagonal"]
    for resolution in (64, 256):
        v, _ = surf.tessellate(resolution)
        assert surf.distances(v).max() <= 1e-7 * diag, resolution
    uv, _ = surf.tessellation_uv(64)
    t = 1e-3 * diag * np.where(np.arange(len(uv)) % 2, 1.0, -1.0)
    p = surf(uv) + t[:, None] * surf.normals(uv)
    d = surf.distances(p)
    # (one of the 3086 points, since the face check samples the border edges too and the net
    # differs, ends in another basin 4e-5 from its foot in the parameters, 5.1e-7 of the
    # diagonal farther: forty-fifth session)
    assert np.all(d <= np.abs(t) + 1e-6 * diag)
    assert np.mean(np.abs(d - np.abs(t)) <= 1e-7 * diag) > 0.95
    np.testing.assert_allclose(np.linalg.norm(surf.closest_points(p) - p, axis=1), d,
                               rtol=0, atol=1e-12 * diag)


def test_closest_points_of_a_cloud_s_data_take_one_descent_but_agree_with_two(monkeypatch):
    """A cloud's points near its surface descend from their projection only, not also from
    the nearest tessellation vertex, when that start is within CLOSEST_SAME_BASIN steps of where
    they ended (2.6x faster at a fit's data points); at the data of a fit with a sharp step the
    distances agree with those of both descents to 1e-6 of the diagonal (4.8e-5 at 20 of
    the 10 000 points of the step tile, where the nearest start found a closer place on the
    step's wall), and at points farther off the surface both are more often taken."""
    xy = np.random.default_rng(5).random((6000, 2))
    z = 0.3 * np.tanh((xy[:, 0] + 0.3 * xy[:, 1] - 0.6) / 0.01) + 0.1 * np.sin(5 * xy[:, 1])
    z += np.random.default_rng(6).normal(0, 2e-3, len(z))
    data = np.c_[xy, z]
    surf = fit_surface(data, tolerance=2e-3, max_control_points=600)
    v, _ = surf.tessellate(96)
    lo, hi = v.min(axis=0), v.max(axis=0)
    off = np.random.default_rng(7).uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (3000, 3))
    calls = []
    newton = TCBSurface._newton_closest

    def counted(self, p, *args, **kw):
        calls.append(len(p))
        return newton(self, p, *args, **kw)

    monkeypatch.setattr(TCBSurface, "_newton_closest", counted)
    one = {"data": surf.distances(data)}
    assert calls[0] == len(data) and calls[1] < 0.05 * len(data)  # (the second descent's)
    calls.clear()
    one["off"] = surf.distances(off)
    assert calls[1] > 0.3 * len(off)  # (1322 of 3000)
    monkeypatch.setattr(core.surface, "CLOSEST_SAME_BASIN", -1.0)  # every point, both starts
    both = {"data": surf.distances(data), "off": surf.distances(off)}
    diag = surf.report["diagonal"]
    for k in one:
        # (within the descents' stopping tolerance, CLOSEST_DISTANCE_TOL: the other starts,
        # TCBSurface._other_starts, are picked from each search's own first result, so neither
        # search's starts contain the other's; 9.3e-11 at 1 of the 3000 points measured)
        assert np.all(one[k] >= both[k] - 1e-9 * diag)
        assert np.all(one[k] <= both[k] + 1e-6 * diag)  # (1.0e-9 and 2.1e-10 measured)
    assert np.all(one["data"] <= surf.errors * (1 + 1e-9) + 1e-12)


def test_closest_points_in_chunks_report_progress_cancel_and_equal_one_pass(nefertiti,
                                                                            monkeypatch):
    """Closest points run in chunks of CLOSEST_CHUNK points (Blender's Deviation Map shows
    the progress and Esc stops it): the callback hears of 0, each chunk and the end; the
    result is that of one pass bit for bit (each point is computed on its own); a callback
    that returns True stops it with CancelledError and nothing else."""
    surf = nefertiti[2]
    v, _ = surf.tessellate(40)
    rng = np.random.default_rng(3)
    p = v[rng.integers(0, len(v), 1000)] + rng.normal(0, 0.02 * surf.report["diagonal"], (1000, 3))
    monkeypatch.setattr(core.surface, "CLOSEST_CHUNK", 10**9)
    whole = surf._closest(p)
    monkeypatch.setattr(core.surface, "CLOSEST_CHUNK", 300)
    reports = []
    chunked = surf._closest(p, callback=lambda r: reports.append(dict(r)))
    for a, b in zip(whole, chunked):
        np.testing.assert_array_equal(a, b)
    assert [r["points_done"] for r in reports] == [0, 300, 600, 900, 1000]
    assert all(r["points"] == 1000 for r in reports)
    np.testing.assert_array_equal(surf.distances(p, callback=lambda r: False), whole[1])
    seen = []
    with pytest.raises(CancelledError, match="cancelled after 600 of 1000 points"):
        surf.closest_points(p, callback=lambda r: seen.append(r["points_done"]) or
                            r["points_done"] >= 600)
    assert seen == [0, 300, 600]
    with pytest.raises(InvalidInputError, match="callback must be a function"):
        surf.distances(p, callback=5)
    # as the fit's: True cancels, None or False go on, anything else is refused (1 or "no"
    # had cancelled: user test)
    for answer in (1, "no"):
        with pytest.raises(InvalidInputError, match="must return None or False .* or True"):
            surf.distances(p, callback=lambda r, a=answer: a)


def test_the_surface_is_nan_where_its_basis_is_not_a_partition_of_unity(nefertiti):
    """Beyond the border rings the basis fades to 0 and the surface would be pulled towards the
    origin: there the surface, its derivatives and normals are NaN, and covers() says so; the
    data's domain is covered and finite."""
    surf = nefertiti[2]
    g = np.linspace(-4, 4, 81)
    uv = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    sums = np.asarray(surf.space.evaluate(uv).sum(axis=1)).ravel()
    covered = surf.covers(uv)
    np.testing.assert_array_equal(covered, np.abs(sums - 1) <= 1e-9)
    assert covered[surf.domain_contains(uv)].all()  # the domain of the mesh's map
    assert not covered.all() and (sums[~covered] < 1 - 1e-9).any()
    for values in (surf(uv), surf.derivative(uv, (1, 0)), surf.derivative(uv, (0, 2)),
                   surf.normals(uv)):
        assert np.isnan(values[~covered]).all()
        assert np.isfinite(values[covered]).all()
    tess_uv, _ = surf.tessellation_uv(64)
    assert surf.covers(tess_uv).all()
    inside = covered & surf.domain_contains(uv)
    np.testing.assert_allclose(surf(uv[inside]), surf.evaluation_matrix(uv[inside])
                               @ surf.control_points, rtol=0, atol=1e-12)


def test_outliers_are_refused_by_name_or_left_out_as_if_they_were_not_there():
    xy = np.random.default_rng(2).random((2000, 2))
    clean = np.c_[xy, franke(*xy.T)]
    for stray in ([30.0, 30.0, 0.3], [0.5, 0.5, 30.0]):  # far in the plane; a spike
        points = clean.copy()
        points[0] = stray
        with pytest.raises(InvalidInputError, match=r"1 of the 2000 points .* #0 .*drop_outliers"):
            fit_surface(points, max_control_points=200)
        dropped = fit_surface(points, max_control_points=200, drop_outliers=True)
        without = fit_surface(points[1:], max_control_points=200)
        assert dropped.report["outliers"] == 1 and dropped.report["points"] == 1999
        assert np.isnan(dropped.errors[0])
        np.testing.assert_array_equal(dropped.errors[1:], without.errors)
        np.testing.assert_array_equal(dropped.coefficients, without.coefficients)
        np.testing.assert_array_equal(dropped.tessellate(32)[0], without.tessellate(32)[0])
        assert dropped.report["rms_rel"] <= 2e-3  # the budget of 200 ends the loop
    assert fit_surface(clean, max_control_points=200).report["outliers"] == 0


def test_two_scans_a_little_apart_are_reported_as_layers_and_noise_is_not():
    """Two copies of a terrain scan 0.1 apart (5 mm noise): closer than the fold check can see,
    the surface runs between them with the errors of noise (user test L2). The report names
    the layers and their distance; the same scan with 5 cm noise, twice as large an RMS, does
    not, nor does a clean fit."""
    rng = np.random.default_rng(3)
    xy = rng.random((3000, 2)) * 4
    scan = np.c_[xy, 0.3 * np.sin(xy[:, 0])]
    both = np.vstack([scan, scan + [0.0, 0.0, 0.1]]) + rng.normal(0.0, 0.005, (6000, 3))
    with pytest.warns(RuntimeWarning, match=r"two layers about 0\.\d+ apart .*align the scans"):
        layered = fit_surface(both)
    assert 0.095 < layered.report["layers"] < 0.105
    noisy = scan + rng.normal(0.0, 0.05, scan.shape)
    for cloud in (noisy, scan):
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            assert fit_surface(cloud).report["layers"] == 0.0
    # layers over part of the surface: a second strip, 0.1 higher, over the upper 40% of the
    # first and on beyond it (strips of an airborne scan overlapping: not seen in the whole,
    # user test)
    xy2 = rng.random((3000, 2)) * 4 + [0.0, 2.4]
    strips = np.vstack([scan, np.c_[xy2, 0.3 * np.sin(xy2[:, 0]) + 0.1]])
    strips += rng.normal(0.0, 0.005, strips.shape)
    with pytest.warns(RuntimeWarning, match=r"two layers about 0\.\d+ apart"):
        partial = fit_surface(strips)
    assert 0.09 < partial.report["layers"] < 0.11


def test_drop_outliers_on_a_mesh_without_spikes_changes_nothing(nefertiti):
    """drop_outliers=True on a mesh without spike vertices leaves none out, without a word (it
    had warned that it applied to point clouds only)."""
    points, faces, _ = nefertiti
    kw = dict(max_control_points=150, max_iterations=2)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="drop_outliers")
        dropped = fit_surface(points, faces, drop_outliers=True, **kw)
    plain = fit_surface(points, faces, **kw)
    assert dropped.report["outliers"] == 0 and dropped.report["points"] == len(points)
    np.testing.assert_array_equal(dropped.control_points, plain.control_points)


def test_a_mesh_s_spike_vertex_is_named_or_dissolved_and_the_others_fit_as_without_it(
        monkeypatch):
    """A grid mesh (spacing 0.05) with one vertex raised by 10 or 1e4, inside or on the border
    (user test: its faces held it in the fit, which missed the other vertices by up to 0.16
    with 715 control points, by 81 for 1e4, on the border 0.094 with 211; 4.2e-3 with 62
    without the spike): an OutlierError names it and drop_outliers; with drop_outliers=True it
    is left out (NaN error, ``report["outliers"]`` 1, no loose vertex), and the others are
    fitted within 1.1x the spike-free fit's max error with its control points (2.7e-3 and
    3.2e-3, 61-62 control points); refine() with the same faces, and with the mesh stored in
    another order, leaves it out again."""
    from meshes import spiky_grid

    clean = fit_surface(*spiky_grid())
    for row, dz in ((620, 10.0), (620, 1e4), (20, 10.0)):
        p, f = spiky_grid({row: dz})
        with pytest.raises(OutlierError, match=rf"sticks out of it as a spike \(outliers: "
                           rf"#{row} .*Move or delete the vertex.*drop_outliers=True") as err:
            fit_surface(p, f)
        assert list(err.value.indices) == [row]
        surf = fit_surface(p, f, drop_outliers=True)
        rep = surf.report
        assert (rep["outliers"], rep["loose_vertices"], rep["points"]) == (1, 0, len(p) - 1)
        assert np.isnan(surf.errors[row])
        others = np.delete(np.arange(len(p)), row)
        assert np.max(surf.errors[others]) <= 1.1 * np.max(clean.errors[others])
        assert rep["control_points"] <= 1.05 * clean.report["control_points"]
    # three in a row: the middle one's ring is bent by both others, so it is found once they
    # are dissolved (core.parameterize._MESH_SPIKE_ROUNDS); a corner pair
    for rows in ([620, 621, 622], [0, 1]):
        p3, f3 = spiky_grid({row: 10.0 for row in rows})
        with pytest.raises(OutlierError) as err:
            fit_surface(p3, f3)
        assert list(err.value.indices) == rows
        three = fit_surface(p3, f3, drop_outliers=True)
        others = np.delete(np.arange(len(p3)), rows)
        assert three.report["outliers"] == len(rows) and np.isnan(three.errors[rows]).all()
        assert np.max(three.errors[others]) <= 1.1 * np.max(clean.errors[others])
    # (the corner pair's second is found in the second round; the share of a rough mesh is
    # held over all rounds: at a share of 1 vertex, the first round's alone)
    import core.parameterize as pz
    monkeypatch.setattr(pz, "_MESH_SPIKE_MAX_SHARE", 1e-9)
    with pytest.raises(OutlierError) as err:
        fit_surface(p3, f3)
    assert list(err.value.indices) == [1]
    monkeypatch.undo()
    again = surf.refine(p, f, max_iterations=1)
    assert again.report["outliers"] == 1 and np.isnan(again.errors[20])
    order = np.random.default_rng(0).permutation(len(p))
    back = np.argsort(order)
    moved = surf.refine(p[order], back[f], max_iterations=1)
    assert moved.report["outliers"] == 1 and np.flatnonzero(~moved.parameterization.used) == [back[20]]


def test_closest_points_of_points_off_the_surface_lie_on_the_trimmed_surface(nefertiti):
    """Points all around a cloud's and a mesh's surface: their closest parameters are in the
    data's domain (before, 15-20% of them were on the extension over the border rings, at
    distances up to 0.1 of the diagonal below any point of the surface), and no distance is
    above the nearest vertex of the starting tessellation; ``closest_points`` are the surface
    there."""
    xy = np.random.default_rng(3).random((1500, 2))
    cloud = fit_surface(np.c_[xy, franke(*xy.T)], max_control_points=200)
    for surf in (cloud, nefertiti[2]):
        v, _ = surf.tessellate(96)
        lo, hi = v.min(axis=0), v.max(axis=0)
        q = np.random.default_rng(4).uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (300, 3))
        uv = surf.closest_parameters(q)
        assert surf.domain_contains(uv).all()
        # the wedge test of the convex domain agrees with the polygon test
        probe = np.random.default_rng(5).uniform(-1.3, 1.3, (20000, 2))
        np.testing.assert_array_equal(surf._in_domain(probe), surf.domain_contains(probe))
        d = surf.distances(q)
        np.testing.assert_allclose(d, np.linalg.norm(surf(uv) - q, axis=1), rtol=1e-12)
        assert (d <= cKDTree(v).query(q)[0] + 1e-12 * np.linalg.norm(hi - lo)).all()
        # the feet: the surface at those parameters, at those distances
        feet = surf.closest_points(q)
        np.testing.assert_allclose(feet, surf(uv), rtol=0, atol=1e-12 * np.linalg.norm(hi - lo))
        np.testing.assert_allclose(np.linalg.norm(feet - q, axis=1), d, rtol=1e-12)


def test_points_around_the_trimmed_edge_find_their_closest_point_along_it(nefertiti):
    """Points near the edge of a mesh's and a cloud's surface whose closest point lies on that
    edge: the descent, pushed back onto the edge at each step, had stalled short of it (user
    test: 286 of 2000 points around patch-01's edge came out up to 33% farther than a known
    point of the surface). No distance is above that of the nearest of many known points."""
    xy = np.random.default_rng(3).random((1500, 2))
    cloud = fit_surface(np.c_[xy, franke(*xy.T)], max_control_points=200)
    for surf in (cloud, nefertiti[2]):
        size = surf.report["diagonal"]
        poly = np.asarray(surf.parameterization.domain_polygon)
        t = np.linspace(0.0, 1.0, 100, endpoint=False)[:, None]
        rim = np.concatenate([a + (b - a) * t for a, b in zip(poly, np.roll(poly, -1, axis=0))])
        uv, _ = surf.tessellation_uv(200)
        known = cKDTree(surf(np.vstack([uv, rim])))
        edge = surf(rim)
        rng = np.random.default_rng(6)
        q = edge[rng.integers(0, len(edge), 1500)] + rng.normal(size=(1500, 3)) * 0.01 * size
        bound = known.query(q)[0]
        over = surf.distances(q) - bound
        assert np.count_nonzero(over > 1e-4 * size) <= 2, np.sort(over)[-5:] / size
        assert over.max() < 5e-4 * size


@pytest.fixture(scope="module")
def three_peaks():
    points, faces = read_geometry(DATA / "three_peaks.off")
    return points, faces, fit_surface(points, faces)


def test_tessellation_refines_where_the_mesh_map_compresses_and_ignores_the_control_points(
    three_peaks,
):
    """three_peaks' map to the disk squeezes steep walls (mesh edges up to 46x longer in 3D per
    uv length than the median): a uniform uv grid at resolution 64 left input vertices 8% of the
    diagonal from every surface vertex. Refined by the vertex stretch, the surface mesh comes
    within 2%; its parameters depend on the data only, so an edited surface keeps them."""
    points, faces, surf = three_peaks
    diag = np.linalg.norm(np.ptp(points, axis=0))
    verts, tris = surf.tessellate(64)
    gap, _ = cKDTree(verts).query(points)
    assert gap.max() < 0.02 * diag
    edges = np.linalg.norm(verts[tris] - verts[tris[:, [1, 2, 0]]], axis=2)
    assert edges.max() < 5 * np.median(edges)
    uv, tri = surf.tessellation_uv(64)
    moved = surf.with_control_points(surf.control_points * 1.5)
    uv2, tri2 = moved.tessellation_uv(64)
    np.testing.assert_array_equal(uv, uv2)
    np.testing.assert_array_equal(tri, tri2)
    # counter-clockwise, or clockwise for faces wound against the canonical winding
    # (three_peaks.off is: its tessellation faces the way of its faces)
    assert surf.parameterization.flipped
    assert np.all(orient2d(uv[tri[:, 0]], uv[tri[:, 2]], uv[tri[:, 1]]) > 0)
    # saved with the surface; a file from before the stretch existed falls back to the density
    back = TCBSurface.from_bytes(surf.to_bytes())
    np.testing.assert_array_equal(back.parameterization.stretch, surf.parameterization.stretch)
    np.testing.assert_array_equal(back.tessellation_uv(64)[0], uv)
    arrays = dict(np.load(io.BytesIO(surf.to_bytes())))
    del arrays["param_stretch"]
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    old = TCBSurface.from_bytes(buf.getvalue())
    assert old.parameterization.stretch is None
    assert len(old.tessellate(64)[0]) > 0


def test_edge_splits_keep_a_conforming_ccw_mesh_of_the_same_area():
    """``core.surface._split_edges`` on a Delaunay mesh with random marks (by a hash of the
    midpoint, so both triangles of an edge agree): one new vertex per marked edge, at its
    midpoint; the marked edges are gone and their halves are there; every triangle CCW, each
    edge in one or two triangles, Euler characteristic and area unchanged."""
    from scipy.spatial import Delaunay

    from core.surface import _split_edges

    rng = np.random.default_rng(3)
    uv = rng.random((400, 2))
    tri = Delaunay(uv).simplices
    tri = np.where((orient2d(*(uv[tri[:, k]] for k in range(3))) < 0)[:, None],
                   tri[:, [0, 2, 1]], tri)

    def mark(length, mid):
        return np.sin(1e4 * mid[:, 0]) * np.cos(7e3 * mid[:, 1]) > 0.2

    ends = np.unique(np.sort(tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    marked = mark(None, 0.5 * (uv[ends[:, 0]] + uv[ends[:, 1]]))
    new_uv, same, new = _split_edges(uv, tri, mark)
    new_tri = np.vstack([same, new])
    assert len(new) and 0.2 < marked.mean() < 0.6
    # the triangles kept have no marked edge, and no later round would mark one of theirs
    kept = np.sort(same[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    assert not mark(None, 0.5 * (uv[kept[:, 0]] + uv[kept[:, 1]])).any()
    assert len(new_uv) == len(uv) + marked.sum()
    np.testing.assert_array_equal(new_uv[: len(uv)], uv)
    doubled = orient2d(*(new_uv[new_tri[:, k]] for k in range(3)))
    assert np.all(doubled > 0)
    assert doubled.sum() == pytest.approx(orient2d(*(uv[tri[:, k]] for k in range(3))).sum(),
                                          rel=1e-12)
    e = np.sort(new_tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges, uses = np.unique(e, axis=0, return_counts=True)
    assert uses.max() == 2
    assert len(new_uv) - len(edges) + len(new_tri) == len(uv) - len(ends) + len(tri) == 1
    have = set(map(tuple, edges))
    mids = {tuple(p): i for i, p in enumerate(new_uv)}
    for (a, b) in ends[marked]:
        m = mids[tuple(0.5 * (uv[a] + uv[b]))]
        assert (a, b) not in have and (min(a, m), max(a, m)) in have and (min(b, m), max(b, m)) in have
    assert len(_split_edges(uv, tri, lambda length, mid: np.zeros(len(mid), bool))[2]) == 0


def test_a_long_thin_strip_is_tessellated_several_triangles_wide():
    """A road 250 times longer than wide with a 0.32 m crown: 64 steps along its length made a
    mesh one triangle wide (143 triangles), 0.29 m off the fitted surface; at least
    TESSELLATION_MIN_ACROSS steps across keep it within a few centimetres."""
    from core.surface import TESSELLATION_MIN_ACROSS

    rng = np.random.default_rng(1)
    xy = np.c_[rng.uniform(0, 2000, 2000), rng.uniform(0, 8, 2000)]
    z = 0.02 * xy[:, 0] + 0.05 * np.sin(xy[:, 0] / 50) - 0.02 * (xy[:, 1] - 4) ** 2
    surf = fit_surface(np.c_[xy, z], tolerance=0.01, relative=False)
    uv, tri = surf.tessellation_uv(64)
    across = np.ptp(uv, axis=0).min()
    edges = np.linalg.norm(uv[tri] - uv[tri[:, [1, 2, 0]]], axis=2)
    assert np.median(edges) <= 1.01 * across / TESSELLATION_MIN_ACROSS
    sag = np.linalg.norm(surf(uv[tri].mean(axis=1)) - surf(uv)[tri].mean(axis=1), axis=1)
    assert sag.max() < 0.05


def test_a_cloud_s_tessellation_grid_follows_its_enclosing_rectangle():
    """The parameter axes of a square cloud follow its principal directions, which are
    arbitrary: Franke's square got 2335 vertices at resolution 64 turned any way (the square
    filled half its parameter box), and 4363 along the axes with a projection given (user
    test). The grid now runs along the smallest rectangle enclosing the domain: the count of
    the square along the axes at every turn, and the grid's lines along the square's sides."""
    from core.surface import _lattice_frame

    rng = np.random.default_rng(0)
    xy = rng.random((3000, 2))
    pts = np.c_[xy, np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1])]
    # along the axes: x and y are the parameter axes (a projection given along z)
    aligned = len(fit_surface(pts, tolerance=1e-2, max_iterations=2,
                              projection="z").tessellation_uv(32)[0])
    for degrees in (0.0, 20.0, 45.0):
        a = np.radians(degrees)
        turn = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        surf = fit_surface(pts @ turn.T, tolerance=1e-2, max_iterations=2)
        uv, tri = surf.tessellation_uv(32)
        assert abs(len(uv) - aligned) <= 0.02 * aligned, (degrees, len(uv), aligned)
        # the edges run along the square's sides (two of the three edges of a grid triangle;
        # a grid along the diagonals would have a third of them so)
        xyz = surf(uv) @ turn  # turned back
        edges = np.concatenate([xyz[tri[:, (k + 1) % 3]] - xyz[tri[:, k]] for k in range(3)])
        slope = np.degrees(np.arctan2(edges[:, 1], edges[:, 0])) % 90
        along = np.minimum(slope, 90 - slope) < 0.5
        assert 0.6 < along.mean() < 0.7, (degrees, along.mean())
    # a polygon along the axes keeps them; a thin diagonal strip turns
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    assert _lattice_frame(square) is None
    strip = np.array([[0, 0], [1, 1], [0.9, 1.1], [-0.1, 0.1]])
    rot = _lattice_frame(strip)
    assert rot is not None and abs(abs(rot[0, 0]) - np.sqrt(0.5)) < 1e-9


def test_a_cloud_scanned_in_lines_is_tessellated_between_them_and_a_notch_is_not():
    """A cloud's tessellation leaves out what is far from the data (an L-shaped cloud's
    notch), but the gaps between the lines of a scan made in lines are no holes: 10 profiles
    0.11 apart, 1000 points each, tessellated at 256 covered 0.11 of the area (its points
    are 0.001 apart along the lines; user test). Nor do the lines set off the swing check
    (the slab of a place's nearest points, all on one line, bounds nothing beside it: 20
    profiles fitted within 6e-4 of the function were flagged at 1826 places)."""
    f = lambda x, y: 0.2 * np.sin(3 * x) * np.cos(2 * y)  # noqa: E731
    # (measured 8.4e-3 and 5.9e-4 with 150 control points; since a start that meets the
    # tolerance by far is followed by coarser ones, 63 and 52: 1.3e-2 and 4.9e-3)
    for lines, off in ((10, 0.02), (20, 8e-3)):
        xy = np.c_[np.repeat(np.linspace(0, 1, lines), 1000), np.tile(np.linspace(0, 1, 1000),
                                                                        lines)]
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # (no warning: no swing)
            surf = fit_surface(np.c_[xy, f(*xy.T)])
        assert surf.report["swings"]["places"] == 0
        for resolution in (64, 256) if lines == 10 else (256,):
            V, T = surf.tessellate(resolution)
            a, b, c = (V[T[:, k], :2] for k in range(3))
            area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]).sum()
            assert area > 0.99, (resolution, area)
            # between the lines the fairing holds the surface
            assert np.abs(V[:, 2] - f(V[:, 0], V[:, 1])).max() < off
    q = np.random.default_rng(0).random((4000, 2))
    q = q[~((q[:, 0] > 0.5) & (q[:, 1] > 0.5))]
    V, T = fit_surface(np.c_[q, f(*q.T)], max_iterations=2).tessellate(128)
    centre = V[T].mean(axis=1)[:, :2]
    assert not ((centre[:, 0] > 0.6) & (centre[:, 1] > 0.6)).any()


def test_a_finer_tessellation_of_a_steep_mesh_is_never_coarser(three_peaks):
    """The edge-split rounds run at every resolution: they were skipped above resolution ~250,
    where three_peaks' surface mesh then had a 3x longer longest edge and 10x the sag at 251
    than at 250."""
    points, faces, surf = three_peaks

    def longest_edge(resolution):
        v, t = surf.tessellate(resolution)
        return float(np.linalg.norm(v[t] - v[t[:, [1, 2, 0]]], axis=2).max())

    at = {r: longest_edge(r) for r in (250, 251, 320)}
    assert at[251] <= 1.1 * at[250] and at[320] <= at[250]


def test_distances_to_the_fitted_data_are_at_most_the_fit_errors(three_peaks):
    """The closest point search also starts from the surface at the data's own parameters, so
    a data point is never reported farther than its fit error (refined three_peaks: the search
    from the tessellation alone reported 1.45 against a largest error of 0.145)."""
    points, faces, surf = three_peaks
    for s in (surf, surf.refine(points, faces, tolerance=0, max_iterations=2)):
        d = s.distances(points)
        assert np.all(d <= s.errors * (1 + 1e-9) + 1e-12)


def test_wrong_shaped_parameters_directories_and_npy_files_get_specific_errors(nefertiti, tmp_path):
    """An (m, 3) array is not reshaped into pairs (12 numbers made 6 wrong points), a folder
    is not "no such file", and a .npy is not a surface file with numpy's words."""
    _, _, surf = nefertiti
    uv = surf.tessellation_uv(8)[0][:4]
    np.testing.assert_array_equal(surf(uv[0]), surf(uv[:1]))  # one (2,) point is one row
    with pytest.raises(InvalidInputError, match=r"\(m, 2\) array of \(u, v\); got shape \(4, 3\)"):
        surf(np.c_[uv, uv[:, :1]])
    assert surf([]).shape == (0, 3)
    with pytest.raises(InvalidInputError, match=r"\(N, 3\) array of x, y, z coordinates; got shape \(4, 2\)"):
        surf.distances(uv)
    with pytest.raises(FileFormatError, match="is a folder"):
        read_geometry(tmp_path)
    np.save(tmp_path / "x.npy", np.zeros(3))
    with pytest.raises(FileFormatError, match=r"not a TCB surface file \(a \.npz archive"):
        TCBSurface.load(tmp_path / "x.npy")


def test_duplicated_points_do_not_refine_the_tessellation():
    """The density that drives the tessellation's refinement counts distinct parameters: a
    cloud given twice gets the same surface mesh (doubled clouds got 14-31% more vertices)."""
    points = ridge_cloud(3000)
    once = fit_surface(points, max_iterations=1)
    twice = fit_surface(np.vstack([points, points]), max_iterations=1)
    a, b = once.tessellation_uv(48)[0], twice.tessellation_uv(48)[0]
    assert a.shape == b.shape  # (the parameters of the doubled cloud differ in the last bits)
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_a_coarse_mesh_fitted_far_from_its_faces_is_reported_and_warned_of(monkeypatch):
    """A CAD plate meshed with long thin faces (34 vertices) whose slope meets a flat at a
    crease: the report's max at the vertices was 0.019 mm, while the surface was up to 0.81 mm
    off the faces, with no word (user test). The errors at the points sampled on the faces
    are reported, and warned of when far above those at the vertices. (On the flat faces'
    samples, as then. Seed 1: the samples are drawn in an order of the faces' corners'
    coordinates, and seeds 0-5 give 1.9, 4.9, 4.6, 3.8, 6.6 and 5.6 times the max at the
    vertices. On the C^1 surface through the vertices the fit keeps about as close to the plate:
    seeds 0-3 0.35-0.62 mm off at most, against 0.28-0.60 on the flat samples (seed 1: 0.62
    and 0.35). The thirty-first session's one draw, on point-normal triangles, had 0.38
    against 1.7.) The face check (FaceCheck) is off for the first fit: it takes most of the
    gap out (flat samples, seeds 0-5: faces 1.3-18.5x the vertices' max with samples inside
    the faces only, 1.2-3.0x and 0.06-0.16 mm off the plate instead of 0.13-0.25 since it
    samples the border edges too: forty-fifth session), and the words are what is tested."""
    R = 5.0
    xs = np.unique(np.r_[0, 20, 40, 40 + R * np.sin(np.linspace(0, np.pi / 4, 12)), 60, 80, 100])

    def prof(x):
        z = np.zeros_like(x)
        a = (x > 40) & (x <= 40 + R * np.sin(np.pi / 4))
        z[a] = R - np.sqrt(R**2 - (x[a] - 40) ** 2)
        x1, z1 = 40 + R * np.sin(np.pi / 4), R - R * np.cos(np.pi / 4)
        b = (x > x1) & (x <= 60)
        z[b] = z1 + (x[b] - x1)
        z[x > 60] = z1 + 60 - x1
        return z

    X, Y = np.meshgrid(xs, [0.0, 50.0])
    V = np.column_stack([X.ravel(), Y.ravel(), prof(X.ravel())])
    n = len(xs)
    F = np.array([f for j in range(n - 1) for f in ([j, j + 1, n + j + 1], [j, n + j + 1, n + j])])
    samples = core.surface.mesh_samples
    with monkeypatch.context() as m, pytest.warns(RuntimeWarning, match=r"at the points the fit "
                                                                         r"sampled on the mesh's "
                                                                         r"faces"):
        m.setattr(core.surface, "mesh_samples",
                  lambda *a, **k: samples(*a, **{**k, "curved": False}))
        m.setattr(core.surface, "FACE_CHECK", False)  # (the check takes most of it out)
        s = fit_surface(V, F, tolerance=0.01, relative=False, seed=1)
    r = s.report
    assert r["faces_max"] > 4 * r["max"] and r["faces_rms"] > 0
    assert r["faces_max_rel"] == pytest.approx(r["faces_max"] / r["diagonal"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (the net for 34 vertices)
        curved = fit_surface(V, F, tolerance=0.01, relative=False, seed=1)

    def off_plate(surf):
        t = surf.tessellate(200)[0]
        return np.abs(t[:, 2] - prof(t[:, 0])).max()

    assert off_plate(curved) < 1.0 and off_plate(s) < 1.0  # mm, on a plate 100 x 50
    # the bundled meshes are fitted as close to their faces as to their vertices: no word
    verts, faces = read_geometry(DATA / "patch-01.off")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        s = fit_surface(verts, faces, max_iterations=2)
    assert s.report["faces_max"] <= 4 * s.report["max"]
    # ... but with criterion "max" a bound was asked for, and over it on the faces is said
    # (user test: 3e-3 reached at the vertices, 1.9x it on the faces, without a word)
    with pytest.warns(RuntimeWarning, match=r"times the max error asked for"):
        s = fit_surface(verts, faces, criterion="max", tolerance=3e-3)
    r = s.report
    assert r["stop_reason"] == "tolerance reached" and r["max_rel"] <= 3e-3 < r["faces_max_rel"]
    # ... not when it was missed at the vertices too ("it holds at the vertices": review)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = fit_surface(verts, faces, criterion="max", tolerance=1e-5, max_iterations=1).report
    assert r["max_rel"] > 1e-5 and r["faces_max_rel"] > 1e-5
    assert not any("max error asked for" in str(w.message) for w in caught)


def test_a_creased_coarse_mesh_grows_no_fin_between_its_samples():
    """A sheet of 231 vertices bent by 90 degrees (100 x 100, diagonal 173), fitted at 1e-4:
    the surface swung 2.6 off the mesh between the points it fitted, a fin at the crease,
    where the report said 0.074 at the vertices and 0.23 on the faces (user test). Each fit of
    the loop is now checked at samples apart from its own (FaceCheck), and where it strays
    those faces' samples are fitted too (benchmarks/fins.py; 2.6 with FACE_CHECK off), and
    what the report says is within 2x of the truth. The check's samples were inside the
    faces only: with seed 2 the surface went 1.6 off at the border where the crease meets
    it (on a border edge, 2.1 off it), which no sample saw. The check samples the border
    edges too: seeds 0-5 0.51 / 0.22 / 1.62 / 0.28 / 0.19 / 0.22 off before, 0.15 / 0.27 /
    0.30 / 0.34 / 0.35 / 0.26 now (forty-fifth session; the rest is the C^1 surface rounding
    the crease)."""
    V, F = bent_sheet()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (a net of 1000 for 231 vertices)
        s = fit_surface(V, F, tolerance=1e-4, max_control_points=3000, seed=2)
    r = s.report
    off = point_mesh_distance(s.tessellate(256)[0], V, F, k=24)
    assert off.max() < 0.45 and np.percentile(off, 99) < 0.05, (off.max(), np.percentile(off, 99))
    assert sum(h.get("stray_samples", 0) for h in r["history"]) >= r["stray_samples"] > 0
    assert off.max() < 2 * max(r["faces_max"], r["max"])


def test_the_face_check_samples_the_border_edges_whatever_the_order_of_the_faces():
    """The face check (FaceCheck) draws samples on the mesh's border edges as well as inside
    its faces, as far apart along them as the faces' samples are: on the bent sheet's 60
    border edges, each sample on one, at the border of the domain, and the same samples for
    the faces shuffled and each face started at another corner (as mesh_samples' draws); a
    long strip's border gets at most a quarter as many as its faces (review)."""
    from core.surface import FaceCheck, _border_samples, border_edges

    V, F = bent_sheet()
    edges = border_edges(V, F)
    assert len(edges[0]) == 2 * (20 + 10)
    rng = np.random.default_rng(0)
    shuffled = np.roll(F[rng.permutation(len(F))], 1, axis=1)
    other = border_edges(V, shuffled)

    def drawn(faces, edges):
        face, bary = _border_samples(edges, 500, seed=4)
        assert (bary.min(axis=1) == 0).all() and np.allclose(bary.sum(axis=1), 1.0)
        return np.einsum("nk,nkj->nj", bary, V[faces[face]])

    p = drawn(F, edges)
    assert np.allclose(np.sort(p, axis=0), np.sort(drawn(shuffled, other), axis=0), atol=1e-12)
    # each on the sheet's border: y = 0 or 100, or x = 0 (z = 0) or z = 100 (x = 100)
    on = ((p[:, 1] < 1e-9) | (p[:, 1] > 100 - 1e-9) | ((p[:, 0] < 1e-9) & (p[:, 2] < 1e-9))
          | (p[:, 2] > 100 - 1e-9))
    assert on.all()
    assert (p[:, 1] < 1e-9).sum() > 100 and (p[:, 2] > 100 - 1e-9).sum() > 30  # (by length)
    s = fit_surface(V, F, max_iterations=1, tolerance=0)
    par = s.parameterization
    check = FaceCheck(V, par.uv, par.faces, budget=500, floor=1e-6, curved=False)
    check._draw(4000)
    assert point_mesh_distance(check.points, V, F, k=24).max() < 1e-9
    on = ((check.points[:, 1] < 1e-9) | (check.points[:, 1] > 100 - 1e-9)
          | ((check.points[:, 0] < 1e-9) & (check.points[:, 2] < 1e-9))
          | (check.points[:, 2] > 100 - 1e-9))
    # the border's 600 units of length at the faces' spacing (20 000 / 4000)^0.5: 269
    assert on.sum() == len(check.uv) - 4000 == 269, (on.sum(), len(check.uv))
    # a long strip (1 x 400): its border, 802 long, would take 1604 samples; a quarter at most
    x = np.repeat(np.linspace(0.0, 400.0, 401), 2)
    strip = np.c_[x, np.tile([0.0, 1.0], 401), np.zeros(802)]
    k = 2 * np.arange(400)
    tri = np.r_[np.c_[k, k + 2, k + 3], np.c_[k, k + 3, k + 1]]
    long = FaceCheck(strip, strip[:, :2], tri, budget=500, floor=1e-6, curved=False)
    long._draw(2000)
    assert len(long.uv) == 2000 + 500


def test_the_face_check_returns_the_samples_of_the_faces_where_a_fit_strays():
    """FaceCheck on a flat grid mesh (uv = xy) and a spline fitted to it exactly: nothing
    strays; with one control point moved up by 1 (the errors at the fitted points still 0),
    the samples it returns lie on the faces where the moved function's surface strays, are
    on the mesh (z = 0), and leave the pool: the next check returns other samples."""
    from core import build_space, border_rings, default_ring_count
    from core.surface import FaceCheck

    g = np.linspace(0.0, 1.0, 11)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    i, j = (a.ravel() for a in np.meshgrid(np.arange(10), np.arange(10)))
    a = j * 11 + i
    faces = np.r_[np.c_[a, a + 1, a + 12], np.c_[a, a + 12, a + 11]]
    points, uv = np.c_[x, y, np.zeros_like(x)], np.c_[x, y]
    rng = np.random.default_rng(3)
    knots = np.vstack([rng.uniform(0.05, 0.95, (30, 2)),
                       border_rings([-1e-6] * 2, [1 + 1e-6] * 2, 0.2,
                                    rings=default_ring_count(2), seed=0)])
    space = build_space(knots, 2)
    fit = fit_control_points(space, uv, points)
    assert fit.max < 1e-9
    check = FaceCheck(points, uv, faces, budget=500, floor=1e-6, curved=False)
    assert check(space, fit.control_points, uv, fit.errors) is None
    centre = space.evaluate(np.array([[0.5, 0.5]])).toarray()[0]
    moved = fit.control_points.copy()
    k = int(np.argmax(centre))
    moved[k, 2] += 1.0
    x1, p1 = check(space, moved, uv, fit.errors)
    assert len(x1) and int(np.count_nonzero(~check.free)) == len(x1)  # (the pool: 2000, 4000)
    assert np.abs(p1[:, 2]).max() < 1e-12  # (samples of the flat mesh)
    # each returned sample is on a face that meets the moved function's support: within a
    # face's diameter (0.14) of it
    fine = np.c_[[a.ravel() for a in np.meshgrid(*[np.linspace(0, 1, 201)] * 2)]].T
    inside = fine[np.asarray(space.evaluate(fine)[:, k].todense()).ravel() > 0]
    assert cKDTree(inside).query(x1)[0].max() < 0.15
    assert np.asarray(space.evaluate(x1)[:, k].todense()).ravel().max() > 0
    x2 = check(space, moved, uv, fit.errors)
    if x2 is not None:
        assert not (cKDTree(x1).query(x2[0])[0] == 0).any()


def test_an_insertion_taken_back_after_the_face_check_added_points(monkeypatch):
    """The face check (adaptive_fit's stray_check) appends points after a fit; when the swing
    check then takes that insertion back, the insertion is made again from the fit before it,
    whose steer was made at the points before the append: it had been paired with the longer
    points and raised a broadcasting ValueError (review). A stub check adds 40 points at the
    second fit, whose insertion is made to swing at one place."""
    rng = np.random.default_rng(1)
    uv = rng.random((3000, 2))
    pts = np.column_stack([uv, np.sin(6 * uv[:, 0]) * np.cos(5 * uv[:, 1])])
    calls = {"check": 0, "swing": 0}

    def stray(space, control_points, at, errors):
        calls["check"] += 1
        assert len(errors) == len(at)
        if calls["check"] == 2:
            u = rng.random((40, 2))
            return u, np.column_stack([u, np.sin(6 * u[:, 0]) * np.cos(5 * u[:, 1])])
        return None

    swings = refine.swing_places

    def swing_at_the_second(space, control_points, at, p, e, **kw):
        calls["swing"] += 1
        out = swings(space, control_points, at, p, e, **kw)
        return ((at[:1].copy(),) + tuple(out[1:])) if calls["swing"] == 2 else out

    monkeypatch.setattr(refine, "swing_places", swing_at_the_second)
    opts = refine.RefineOptions(tolerance=1e-5, initial_knots=30, max_iterations=4,
                                max_control_points=3000)
    best, hist, reason = refine.adaptive_fit(uv, pts, opts, diagonal=np.sqrt(3),
                                             n_measured=3000, stray_check=stray)
    # (made again away from the one place, the same knots: the loop stops there)
    assert hist[1]["stray_samples"] == 40 and hist[1]["knots_taken_back"] == 10
    assert reason == refine.SWINGS_LEFT and best.iteration == 1
    assert len(best.fit.errors) == 3000


def test_a_coarse_mesh_whose_net_outgrows_it_is_warned_of():
    """A 4 x 4 grid mesh of a smooth function got 581 control points (its 21 x 21 grid 149):
    its flat faces are data, and the creases between them take many control points; no word
    said so (user test). A net of over COARSE_MESH_RATIO control points per vertex is warned
    of, with the ways to a small net: subdivided, or its vertices as a point cloud, which
    gives one here."""
    from core.surface import COARSE_MESH_RATIO

    v, f = grid_mesh(4)
    with pytest.warns(RuntimeWarning, match=r"the net has \d+ control points for a mesh of 16 "
                                            r"vertices: .*subdivide the mesh first.*fit its "
                                            r"vertices as a point cloud"):
        s = fit_surface(v, f)
    assert s.report["control_points"] > COARSE_MESH_RATIO * 16
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        cloud = fit_surface(v)  # (what the warning advises)
        fine = fit_surface(*grid_mesh(21))
    assert cloud.report["control_points"] < 16 * COARSE_MESH_RATIO
    assert fine.report["control_points"] < 441


def test_a_flat_mesh_with_a_large_net_is_not_said_to_have_creases():
    """A flat 4 x 4 grid and a flat 12-vertex n-gon got the large net's warning that blamed
    "the creases between the mesh's flat faces", which they do not have (user test): the
    largest bend between neighbouring faces decides the words; a creased mesh's warning
    names its largest bend. Since a start that meets the tolerance by far is followed by
    coarser ones (core.refine.SHRINK_TARGET), a flat mesh gets a small net (40 control
    points, was 147): the warning is then made with the probe's knots given."""
    from core.surface import largest_crease

    v, f = grid_mesh(4)
    flat = np.c_[v[:, :2], np.zeros(len(v))]
    assert largest_crease(flat, f) == pytest.approx(0.0, abs=1e-6)
    # two triangles folded by 90 degrees along their shared edge
    assert largest_crease(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]),
                          np.array([[0, 1, 2], [1, 0, 3]])) == pytest.approx(90.0)
    ring = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    ngon = np.c_[np.cos(ring), np.sin(ring), np.zeros(12)]
    for points, faces in ((flat, f), (ngon, [list(range(12))])):
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            assert fit_surface(points, faces, tolerance=0.05).report["control_points"] <= 45
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            s = fit_surface(points, faces, tolerance=0.05, initial_knots=41)
        words = [str(w.message) for w in caught if str(w.message).startswith("the net has")]
        assert len(words) == 1 and s.report["coarse_mesh_crease"] < 1e-3, words
        assert "creases between them" not in words[0]
        assert re.search(r"more than it needs: the mesh is flat \(no creases between its "
                         r"faces\), .*lower max_control_points", words[0]), words[0]
    with pytest.warns(RuntimeWarning, match=r"the creases between them \(up to [\d.]+ "
                                            r"degrees\) take many control points"):
        fit_surface(*grid_mesh(4))


def _coarse_meshes():
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        import coarse_meshes
    finally:
        sys.path.pop(0)
    return coarse_meshes


def test_curved_face_samples_keep_flat_faces_and_creases_flat_and_hug_a_sphere():
    """core.surface.curved_points (PN triangles): at a face's corners the corners themselves;
    on a flat mesh and across a 90-degree crease (its corners there take the faces' own
    normals, CREASE_ANGLE) exactly the flat faces' points; on the facets of a sphere cap of
    55 vertices 5x closer to the sphere than the flat faces' points (RMS 2.4e-3 against
    1.2e-2; its border vertices' normals, of their inner faces only, are up to 9 degrees off
    the sphere's)."""
    from core.surface import curved_points, mesh_samples

    bench = _coarse_meshes()
    (v, f), _ = bench.grid(9, lambda x, y: 0.2 * x - 0.1 * y)
    (c, cf), _ = bench.grid(21, bench.crease)
    for pts, faces in ((v, f), (c, cf)):
        uv = pts[:, :2]
        flat = mesh_samples(pts, uv, faces, 4000, curved=False)
        curved = mesh_samples(pts, uv, faces, 4000)
        np.testing.assert_array_equal(curved[1], flat[1])  # the same parameters
        np.testing.assert_allclose(curved[0], flat[0], atol=1e-12)
    corners = np.repeat(np.eye(3), 4, axis=0)
    face = np.tile(np.arange(4), 3)
    np.testing.assert_allclose(curved_points(c, cf, face, corners),
                               c[cf[face, np.repeat(np.arange(3), 4)]], atol=1e-12)
    (s, sf), off = bench.sphere_cap(2)
    flat = off(mesh_samples(s, s[:, :2], sf, 4000, curved=False)[0])
    curved = off(mesh_samples(s, s[:, :2], sf, 4000)[0])
    assert np.sqrt(np.mean(curved**2)) < 0.25 * np.sqrt(np.mean(flat**2))


def test_curved_face_samples_keep_a_plane_flat_next_to_a_tangent_fillet():
    """An STL-like profile: a plane 3 long in one row of long triangles, a fillet of radius 0.3
    in 4 facets tangent to it, and a wall. The vertex normals along the tangent lines turn with
    the fillet's facets (11 degrees: no crease), and with them the plane's long triangles
    sagged, 5e-3 of the diagonal (a review); a face with a corner inside a flat region
    (FLAT_ANGLE) stays flat, and the fillet's facets still bend towards the arc: on the C^1
    samples (the mesh's own map; they depend on it) 8.4e-4 from the arc (RMS), on the flat
    faces 4.2e-3, on point-normal triangles 8.2e-4."""
    from core.parameterize import parameterize
    from core.surface import mesh_samples

    t = np.radians(np.linspace(0, 90, 5))
    x = np.r_[-3.0, -1.5, 0.3 * np.sin(t), 0.3]
    z = np.r_[0.0, 0.0, 0.3 - 0.3 * np.cos(t), 1.3]
    v = np.array([(a, y, c) for y in (0.0, 1.0) for a, c in zip(x, z)])
    n = len(x)
    f = np.array([q for j in range(n - 1) for q in ([j, j + 1, n + j + 1], [j, n + j + 1, n + j])])
    par = parameterize(v, f)
    uv, f = par.uv, par.faces
    points, _ = mesh_samples(v, uv, f, 20000)
    flat, _ = mesh_samples(v, uv, f, 20000, curved=False)
    on_plane = flat[:, 0] < -1e-9  # (the same random faces and coordinates for both)
    on_wall = flat[:, 2] > 0.3 + 1e-9
    assert np.abs(points[on_plane, 2]).max() < 1e-12
    assert np.abs(points[on_wall, 0] - 0.3).max() < 1e-12
    arc = ~on_plane & ~on_wall

    def off(q):
        return np.abs(np.hypot(q[:, 0], q[:, 2] - 0.3) - 0.3)

    assert np.sqrt(np.mean(off(points[arc]) ** 2)) < 0.3 * np.sqrt(np.mean(off(flat[arc]) ** 2))


def test_a_coarse_mesh_of_a_smooth_shape_is_fitted_as_the_shape_not_its_facets():
    """A cap of a unit sphere meshed with 55 vertices (an icosphere's faces above z = 0.3): on
    the flat faces' samples the fit followed the facets, 750 control points and 4.7e-3 of the
    diagonal (RMS) from the sphere; on curved triangles through the vertices 150 and 1.0e-3
    (benchmarks/coarse_meshes.py)."""
    (v, f), off = _coarse_meshes().sphere_cap(2)
    s = fit_surface(v, f)
    r = s.report
    assert r["stop_reason"] == "tolerance reached" and r["control_points"] < 300
    assert np.sqrt(np.mean(off(s.tessellate(64)[0]) ** 2)) < 2e-3 * r["diagonal"]


def test_a_coarse_curved_mesh_is_not_taken_for_a_swing():
    """Half a cylinder of 34 vertices (Blender's cylinder cut in half): the swing check looked
    at the vertices only, whose neighbourhoods across the long faces are no slab, and flagged
    636 places by up to 0.23 where the surface was within 0.002 of the faces; at tolerance 5e-2
    the smoother refit it set off took smoothness 1.0 and went 7% of the diagonal off (user
    test). A mesh's samples on its faces are data for the check too."""
    a = np.linspace(0, np.pi, 17)
    v = np.vstack([np.c_[np.cos(a), np.sin(a), np.full(17, z)] for z in (-1.0, 1.0)])
    quads = np.array([[i, i + 1, 18 + i, 17 + i] for i in range(16)])
    for kw in ({}, {"tolerance": 5e-2}, {"smoothness": 1e-4}):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            s = fit_surface(v, quads, **kw)
        assert not [w for w in caught if "swings away" in str(w.message)], kw
        r = s.report
        assert r["swings"]["places"] == 0 and r["smoothness"] == 1e-4, kw
        radius = np.hypot(*s.tessellate(64)[0][:, :2].T)
        assert np.abs(radius - 1).max() < 0.02 * r["diagonal"], kw


def test_a_long_corridor_with_points_across_it_is_a_surface_and_a_thread_is_a_curve():
    """A road scan 5 km long and 4 m wide had been refused as "almost on a curve" (its domain
    0.8e-3 as wide as long), with 14-30 point spacings across it (user test)."""
    rng = np.random.default_rng(0)
    n, L, W = 40_000, 5000.0, 4.0  # sqrt(n W / L) = 5.7 spacings across
    x, y = rng.uniform(0, L, n), rng.uniform(-W / 2, W / 2, n)
    P = np.column_stack([x, y, 10 * np.sin(x / 300) - 0.02 * np.abs(y)])
    s = fit_surface(P, tolerance=0.01, relative=False, projection="z", max_control_points=400)
    assert s.report["rms"] < 0.05 and np.isfinite(s(np.asarray(s.parameterization.uv))).all()
    thread = P[:2000] * [1.0, 0.1, 1.0]  # 0.4 m wide: 0.4 spacings across
    with pytest.raises(InvalidInputError, match="the points lie almost on a curve"):
        fit_surface(thread, projection="z")
    # one track wiggling 4 m wide: as many points, but on a curve (it had passed: review)
    x = np.sort(rng.uniform(0, L, n))
    with pytest.raises(InvalidInputError, match="the points lie almost on a curve"):
        fit_surface(np.c_[x, 2 * np.sin(x / 37), 10 * np.sin(x / 300)], projection="z")


def test_a_mesh_of_a_few_large_polygons_is_not_taken_for_transposed_faces():
    # three 11-gons fan out into a disk (review: refused as "transposed" at first)
    t = np.linspace(0, 2 * np.pi, 31)[:-1]
    ring = np.c_[np.cos(t), np.sin(t), 0.1 * np.cos(2 * t)]
    points = np.vstack([[0.0, 0.0, 0.0], ring, 0.5 * ring])
    faces = np.array([[0] + [1 + (10 * k + j) % 30 for j in range(11)] for k in range(3)])
    assert faces.shape == (3, 12)
    surf = fit_surface(points, faces, max_iterations=1)  # (the inner ring: loose vertices)
    assert surf.report["points"] == 31


def test_a_callback_wrapped_by_a_decorator_is_taken_as_it_is_called():
    import functools

    def with_extra(fn):
        @functools.wraps(fn)
        def run(report):
            return fn(report, "extra")
        return run

    @with_extra
    def cb(report, extra):
        return False

    fit_surface(np.random.default_rng(0).random((300, 3)) * [1, 1, 0.1], max_iterations=1,
                max_control_points=100, callback=cb)


def _half_sphere(nu=16, nv=8):
    """A half UV sphere (Blender's primitive cut at the equator): 1 + nu (nv // 2) vertices,
    a fan at the pole and quads split into triangles, oriented outwards."""
    th = np.linspace(0, np.pi / 2, nv // 2 + 1)[1:]
    ph = np.linspace(0, 2 * np.pi, nu + 1)[:-1]
    t, p = (a.ravel() for a in np.meshgrid(th, ph, indexing="ij"))
    verts = np.vstack([[0, 0, 1.0], np.c_[np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]])
    ring = lambda r, j: 1 + r * nu + j % nu  # noqa: E731
    faces = [[0, ring(0, j), ring(0, j + 1)] for j in range(nu)]
    for r in range(nv // 2 - 1):
        for j in range(nu):
            a, b, c, d = ring(r, j), ring(r + 1, j), ring(r + 1, j + 1), ring(r, j + 1)
            faces += [[a, b, c], [a, c, d]]
    return verts, np.array(faces)


def test_the_same_cloud_stored_in_another_order_gets_the_same_surface():
    """A cloud's points shuffled: the same surface (the checks' samples, the fit's draws and
    the swing check take the points in an order of their coordinates, core.geometry.
    coordinate_order; before, 3000 points shuffled got 499 to 507 control points), rows given
    back in the order given, and an outlier error naming the rows of the order given."""
    rng = np.random.default_rng(0)
    xy = rng.random((3000, 2))
    pts = np.c_[xy, np.exp(-((xy - 0.5) ** 2).sum(1) * 8) + 0.2 * np.sin(6 * xy[:, 0])]
    pts = np.vstack([pts, [[0.5, 0.5, 9.0], [3.0, 3.0, 0.0]]])  # two outliers
    base = fit_surface(pts, tolerance=2e-4, drop_outliers=True)
    at, _ = base.tessellation_uv(32)
    assert not base.parameterization.used[-2:].any()
    for _ in range(2):
        perm = rng.permutation(len(pts))
        back = np.argsort(perm)
        surf = fit_surface(pts[perm], tolerance=2e-4, drop_outliers=True)
        assert surf.report["control_points"] == base.report["control_points"]
        np.testing.assert_array_equal(surf.parameterization.used[back], base.parameterization.used)
        np.testing.assert_allclose(surf.parameterization.uv[back], base.parameterization.uv,
                                   atol=1e-12)
        np.testing.assert_allclose(surf.errors[back], base.errors, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(surf(at), base(at), atol=1e-8)
        with pytest.raises(OutlierError) as caught:
            fit_surface(pts[perm], tolerance=2e-4)
        assert sorted(caught.value.indices) == sorted(back[-2:])
        assert f"#{min(back[-2:])} " in str(caught.value)


def test_a_quad_mesh_whose_quads_start_at_other_corners_gets_the_same_surface(tmp_path):
    """Quads are cut along their shorter diagonal (core.geometry.quad_triangles), not from
    their first corner: a 6 x 6 quad grid got 142-335 control points as its quads' corners
    were turned (review); now one surface. The same for a file's quads (core.meshio)."""
    x, y = np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 6), indexing="ij")
    P = np.c_[x.ravel(), y.ravel(), 0.5 * x.ravel() ** 2 + 0.8 * np.sin(3 * y.ravel()) * x.ravel()]
    i = np.arange(36).reshape(6, 6)
    Q = np.c_[i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (a coarse mesh's large net)
        base = fit_surface(P, Q)
    at, _ = base.tessellation_uv(32)
    rng = np.random.default_rng(1)
    for _ in range(3):
        turned = Q[np.arange(len(Q))[:, None], (rng.integers(0, 4, len(Q))[:, None]
                                                 + np.arange(4)) % 4]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            surf = fit_surface(P, turned)
        assert surf.report["control_points"] == base.report["control_points"]
        np.testing.assert_allclose(surf(at), base(at), atol=1e-8)
    # an OBJ file's quads: read as the same triangles (each turned to its least corner)
    cuts = []
    for name, quads in (("plain", Q), ("turned", turned)):
        path = tmp_path / f"{name}.obj"
        path.write_text("".join(f"v {a!r} {b!r} {c!r}\n" for a, b, c in P)
                        + "".join(f"f {a + 1} {b + 1} {c + 1} {d + 1}\n" for a, b, c, d in quads))
        _, tris = read_geometry(path)
        tris = np.array([np.roll(t, -int(np.argmin(t))) for t in tris])
        cuts.append(tris[np.lexsort(tris.T[::-1])])
    np.testing.assert_array_equal(cuts[0], cuts[1])


def _voronoi_height_field():
    """A height field of convex pentagons to heptagons (the Voronoi cells of a jittered
    hexagonal lattice inside the square), counter-clockwise, and its (n, 3) vertices."""
    from scipy.spatial import Voronoi

    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(np.arange(14), np.arange(14)), -1).reshape(-1, 2).astype(float)
    g[:, 0] += 0.5 * (g[:, 1] % 2)
    vor = Voronoi(g / 13 * 2 - 1 + rng.normal(0, 0.02, g.shape))
    polys = [r for r in vor.regions
             if r and -1 not in r and (np.abs(vor.vertices[r]) <= 1.0).all()]
    used = np.unique(np.concatenate(polys))
    number = np.full(len(vor.vertices), -1)
    number[used] = np.arange(len(used))
    xy = vor.vertices[used]
    polys = [number[r] for r in polys]
    polys = [p if np.cross(xy[p] - xy[p].mean(0), np.roll(xy[p], -1, 0) - xy[p].mean(0)).sum()
             > 0 else p[::-1] for p in polys]
    return np.c_[xy, 0.3 * np.sin(2 * xy[:, 0]) * np.cos(1.5 * xy[:, 1])], polys


def test_a_mesh_of_polygons_that_start_at_other_corners_gets_the_same_surface(tmp_path):
    """Polygons of five or more corners are cut by their best ears (core.geometry.
    polygon_triangles), not in fans from their first corner: a height field of 140 convex
    pentagons to heptagons got 107-146 control points as their first corners were turned, and
    2.4e-4 to 4.8e-4 of the diagonal (RMS) from the true surface; now one surface, 2.1e-4
    (/tmp/s34/ngon.py). The same for a file's polygons (core.meshio)."""
    P, polys = _voronoi_height_field()
    assert {len(p) for p in polys} == {5, 6, 7} and len(polys) == 140
    base = fit_surface(P, polys)
    at, _ = base.tessellation_uv(32)
    rng = np.random.default_rng(1)
    for _ in range(2):
        turned = [np.roll(p, rng.integers(len(p))) for p in polys]
        surf = fit_surface(P, turned)
        assert surf.report["control_points"] == base.report["control_points"]
        np.testing.assert_allclose(surf(at), base(at), atol=1e-10)
    verts, _ = base.tessellate(48)
    true = 0.3 * np.sin(2 * verts[:, 0]) * np.cos(1.5 * verts[:, 1])
    assert np.sqrt(np.mean((verts[:, 2] - true) ** 2)) < 3e-4 * np.linalg.norm(np.ptp(P, 0))
    cuts = []
    for name, faces in (("plain", polys), ("turned", turned)):
        path = tmp_path / f"{name}.obj"
        path.write_text("".join(f"v {a!r} {b!r} {c!r}\n" for a, b, c in P)
                        + "".join("f " + " ".join(str(i + 1) for i in p) + "\n" for p in faces))
        _, tris = read_geometry(path)
        tris = np.array([np.roll(t, -int(np.argmin(t))) for t in tris])
        cuts.append(tris[np.lexsort(tris.T[::-1])])
    np.testing.assert_array_equal(cuts[0], cuts[1])


def test_the_same_mesh_stored_in_another_order_gets_the_same_surface():
    """Vertices renumbered, faces shuffled and their corners turned (Blender's Sort Elements;
    bmesh edits leave faces in another order) leave the fit as it was: the map starts its
    boundary loop at the vertex of least coordinates, the samples on the faces are drawn in an
    order of the corners' coordinates and the fit takes the points in such an order
    (core.surface._area_samples, _run). Before, this half sphere got 184 to 494 control
    points (user test)."""
    verts, faces = _half_sphere()
    base = fit_surface(verts, faces)
    rng = np.random.default_rng(3)
    at, _ = base.tessellation_uv(32)
    for _ in range(3):
        perm = rng.permutation(len(verts))
        back = np.argsort(perm)
        shuffled = back[faces][rng.permutation(len(faces))]
        shuffled = np.roll(shuffled, int(rng.integers(1, 3)), axis=1)  # the same orientation
        surf = fit_surface(verts[perm], shuffled)
        assert surf.report["control_points"] == base.report["control_points"]
        np.testing.assert_allclose(surf.errors[back], base.errors, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(surf.parameterization.uv[back], base.parameterization.uv,
                                   atol=1e-12)
        np.testing.assert_allclose(surf(at), base(at), atol=1e-8)
