"""The indicators of a muscle-driven run (``outcomes.muscle_fields``): effort, mean activations and
the spans of full activation, against sums and spans built by hand."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings, strategies as st

from fdbench.outcomes import FULL_ACTIVATION, MAX_SPANS, muscle_fields


def test_effort_and_means_are_the_sums_over_the_samples():
    t = np.linspace(0.0, 1.0, 5)
    a = np.array([[0.1, 0.2], [0.3, 0.4], [0.5, 0.0], [0.2, 0.2], [0.0, 1.0]])
    fields = muscle_fields(["flexor", "extensor"], t, a)
    assert math.isclose(fields["effort"], (0.05 + 0.25 + 0.25 + 0.08 + 1.0) / 5)
    assert math.isclose(fields["flexor_activation_mean"], 0.22)
    assert math.isclose(fields["extensor_activation_mean"], 0.36)
    assert fields["saturation"] == "extensor at 1 s"  # a single sample


def test_no_sample_reached_gives_no_number():
    fields = muscle_fields(["m"], np.zeros(0), np.zeros((0, 1)))
    assert math.isnan(fields["effort"]) and fields["saturation"] is None


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=40))
def test_the_spans_named_are_the_runs_of_full_activation(full):
    t = np.arange(len(full)) * 0.1
    a = np.where(full, 1.0, FULL_ACTIVATION - 0.01)[:, None]
    runs, start = [], None  # the runs of True, by hand
    for k, value in enumerate(full + [False]):
        if value and start is None:
            start = k
        elif not value and start is not None:
            runs.append((start, k - 1))
            start = None
    said = muscle_fields(["m"], t, a)["saturation"]
    if not runs:
        assert said is None
        return
    spans = [f"from {t[a]:.3g} to {t[b]:.3g} s" if a != b else f"at {t[a]:.3g} s" for a, b in runs[:MAX_SPANS]]
    more = f" and {len(runs) - MAX_SPANS} more times" if len(runs) > MAX_SPANS else ""
    assert said == "m " + ", ".join(spans) + more
