"""The sweep's statistics and pictures for every mix of outcomes (issue #29): all held, all
dropped, one sample, one bin, samples on one value, any count. Property-based (Hypothesis)
over the outcome arrays; plain Python (no bpy, no core): engine/sweep.py's functions on rows
as its workers return them."""
import math
import os

import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from addon.engine import sweep

SETTINGS = settings(max_examples=60, deadline=None)


@given(n=st.integers(1, 10**7), data=st.data())
@example(n=7, data=None)          # 0 of 7: the lower end once rounded to 2.8e-17, above p = 0
@example(n=10, data=None)         # 10 of 10: the upper end once rounded to 1 - 1e-16, below p = 1
@settings(max_examples=400, deadline=None)
def test_the_wilson_interval_holds_the_proportion(n, data):
    ks = [0, n] if data is None else [data.draw(st.integers(0, n))]
    for k in ks:
        lo, hi = sweep.wilson(k, n)
        assert 0.0 <= lo <= k / n <= hi <= 1.0, (k, n, lo, hi)
        assert hi - lo <= 1.0 and math.isfinite(lo) and math.isfinite(hi)


def _job(texts, analysis=False):
    return sweep.Job(scene={}, rate=1000.0, hips=np.zeros((1, 1, 3)), has_start=True, times=np.zeros(2),
                     varies=[sweep.parse_vary(t) for t in texts], seed=0, body=0, window=(0, 1),
                     analysis=analysis)


def _rows(job, held, xs, ys):
    rows = []
    for i, h in enumerate(held):
        row = {"sample": i, "seed": i, "held": int(h), "drop_time": None if h else 0.5, "held_time": 1.0 if h else 0.5,
               "max_slip": 0.001 * i, "max_force": 2.0, "closure_time": 0.3 if h else None,
               "min_epsilon": 0.01 if h else None}
        values = [xs[i], ys[i]]
        for v, x in zip(job.varies, values):
            row[v.column] = x
        rows.append(row)
    return rows


SPECS = [("Box.mass=0.05:3",), ("Box.mass=0.05,1,3",), ("Box.mass=0.05:3", "Box.mu_s=0.1:1"), ()]


@st.composite
def outcomes(draw):
    spec = draw(st.sampled_from(SPECS))
    n = draw(st.integers(1, 60))
    held = draw(st.lists(st.booleans(), min_size=n, max_size=n)
                | st.sampled_from([[True] * n, [False] * n]))
    job = _job(spec, analysis=draw(st.booleans()))
    grid = [0.05, 1.0, 3.0]
    same = draw(st.booleans())          # every sample on one value (one bin)
    xs = [grid[i % 3] if "," in "".join(spec[:1]) else (1.0 if same else draw(st.floats(0.05, 3.0)))
          for i in range(n)]
    ys = [draw(st.floats(0.1, 1.0)) for _ in range(n)]
    return job, _rows(job, held, xs, ys)


@given(case=outcomes())
@SETTINGS
def test_summary_and_sensitivity_for_any_outcomes(case):
    job, rows = case
    spec = {"recording": "r.mcap", "fingerprint": "", "body": "Box"}
    s = sweep.summarize(job, rows, spec)
    k = sum(r["held"] for r in rows)
    assert s["held"] == k and s["samples"] == len(rows) and s["p_held"] == k / len(rows)
    assert 0 <= s["ci95"][0] <= s["p_held"] <= s["ci95"][1] <= 1
    for entry in s["sensitivity"].values():
        c = entry["correlation_with_held"]
        assert c is None or -1.0 - 1e-12 <= c <= 1.0 + 1e-12
        for b in entry.get("by_value", []) + entry.get("by_quartile", []):
            assert b["p_held"] is None or 0.0 <= b["p_held"] <= 1.0


@given(case=outcomes())
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])  # two figures each: seconds on a loaded machine
def test_the_pictures_are_drawn_for_any_outcomes(case, tmp_path_factory):
    job, rows = case
    folder = str(tmp_path_factory.mktemp("pictures"))
    paths = sweep.draw_pictures(job, rows, folder)
    assert [os.path.basename(p) for p in paths] == ["map.png", "outcomes.png"]
    for p in paths:
        with open(p, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    rgb = sweep.plain_map(job, rows)                # the picture Blender's Python draws
    assert rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3 and rgb.size
