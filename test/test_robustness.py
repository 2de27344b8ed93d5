"""The robustness matrix: every case stays bounded and tracks within its stated bound.

The cases (start offsets, noise with the noise preset, camera delay, wrong
initial estimates, NaN bursts, dropped frames) live in
:mod:`visual_adaptive_servo.robustness`; ``vas robustness`` prints the same table
that the README shows.
"""

import pytest

from visual_adaptive_servo.robustness import CASES, run_case


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_case_is_bounded_and_tracks(case, tmp_path):
    summary = run_case(case, str(tmp_path), duration=10.0)
    assert not summary["diverged"], summary["divergence_reason"]
    assert summary["max_abs_torque"] <= summary["torque_limit"]
    assert summary["final_rms_true_error_px"] <= case.rms_bound_px
    assert summary["min_estimated_depth"] > 0.0
    if case.faults is not None:
        assert summary["rejected"] > 0, "the injected faults must reach the controller"
