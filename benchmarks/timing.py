"""Timing helpers shared by the benchmark scripts."""

from __future__ import annotations

import time


def time_calls(module, attr: str, label: str, seconds: dict, before=None, after=None) -> None:
    """Replace ``module.attr`` by a wrapper that adds its wall time to ``seconds[label]``;
    ``before()`` / ``after(label)`` run around every call (e.g. tracemalloc peaks)."""
    fn = getattr(module, attr)

    def wrapped(*a, **kw):
        if before is not None:
            before()
        t = time.perf_counter()
        try:
            return fn(*a, **kw)
        finally:
            seconds[label] = seconds.get(label, 0.0) + time.perf_counter() - t
            if after is not None:
                after(label)

    setattr(module, attr, wrapped)


def report_phases(report: dict) -> list[dict]:
    """The per-phase seconds of a ``fit_surface`` report: one dict per iteration, plus the final
    fit on all points when the iterations used a subset (``report["refit"]``)."""
    return [h["phases"] for h in report["history"]] + [report.get("refit", {}).get("phases", {})]
