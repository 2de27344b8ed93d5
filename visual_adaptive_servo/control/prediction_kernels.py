# Copyright 2026 visual_adaptive_servo contributors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The late frame's re-run of :meth:`.prediction.FramePredictor.correct`, compiled with numba.

The numpy code in ``correct`` stays the reference: this kernel evaluates the
same closed form, x_k = P_k (x + sum_{j<k} c_j / P_{j+1}) with
a_k = 1 - dt_k Z_dot_k / Z_k, c_k = dt_k (J_perp q_dot_k / Z_k + b) and P the
running product of the a_k, in the same order (so the same numbers), as one
loop instead of ~10 numpy calls and a stack of the buffer's rate arrays.
The tracker sets ``FramePredictor.rerun`` to :func:`rerun` when its model
runs the compiled backend.  Importing this module imports numba.
"""

from __future__ import annotations

import numpy as np

from ..models.kernels import compiled


@compiled(error_model="numpy")
def _rerun(times, stamp, rates, x, drift):
    k, m2 = rates.shape[0], x.shape[0]
    steps = np.empty((k, m2))
    for j in range(m2):
        P = 1.0
        S = 0.0
        for s in range(k):
            dt = times[s + 1] - (stamp if s == 0 else times[s])
            a = 1.0 - dt * rates[s, 1, j] / rates[s, 2, j]
            c = dt * (rates[s, 0, j] / rates[s, 2, j] + drift[j])
            P = P * a
            S = S + c / P
            steps[s, j] = P * (x[j] + S)
    return steps


def rerun(times, stamp, rates, x, drift):
    """x_hat at ``times[1:]`` from x at ``stamp`` (between times[0] and times[1]).

    ``times`` (k + 1,) the buffer's joint-sample times from the last one at or
    before the stamp, then now; ``rates`` (k, 3, 2m) their (J_perp q_dot, Z_dot,
    Z); ``x`` (2m,) the frame's x_hat at the stamp; ``drift`` b, 0.0 or (2m,).
    Returns (k, 2m).
    """
    x = np.ascontiguousarray(x, dtype=float)
    if np.ndim(drift) == 0:
        drift = np.full(x.shape[0], float(drift))
    return _rerun(np.asarray(times, dtype=float), float(stamp), rates, x,
                  np.ascontiguousarray(drift, dtype=float))
