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

"""Compiled (numba) kernels of the kinematic tensors: the same arithmetic as the numpy code.

The numpy implementations stay the readable reference and the test oracle:
:meth:`.kinematic_regressor.KinematicRegressor.tensors_numpy` and
:meth:`.paper_rrr.PaperRRRCamera.kinematic_tensors_numpy`.  Each kernel here
follows its reference step by step (the same products, sums in the same
order), written as loops over 3-vectors: at n = 7 the numpy version is ~60
small-array calls whose overhead, not the arithmetic, is the cost.

Importing this module imports numba (ImportError without it); compiling is
lazy, at the first call, and cached on disk (``cache=True``) in
:func:`cache_dir`: under ``$NUMBA_CACHE_DIR`` when set, otherwise under
``$XDG_CACHE_HOME/visual_adaptive_servo/numba`` (``~/.cache/...``), a place
that is writable for a read-only (ROS, system) install, in a folder named by
a digest of the package's sources.  numba checks a cached kernel against its
own source file only, not against the kernels and constants it compiled in
from other modules (the law inside the whole sample, the trajectory's blend,
a tolerance): with one folder for every version of the sources, changing
``law_kernels.py`` alone would leave the cached sample running the old law.
When that place is not writable numba falls back to its own places (the
package's ``__pycache__``, then ``~/.cache/numba``); when none is, the
kernels compile at every start.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import math
import os

import numba
import numpy as np
from numba.core import config as numba_config

log = logging.getLogger(__name__)


def cache_dir():
    """Where the compiled kernels are cached (see the module docstring)."""
    base = numba_config.CACHE_DIR
    if not base:
        home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                                ".cache")
        base = os.path.join(home, "visual_adaptive_servo", "numba")
    return os.path.join(base, sources_digest())


@functools.lru_cache(maxsize=None)
def sources_digest(root=None):
    """16 hex digits of SHA-256 over the package's ``.py`` files (relative paths and bytes).

    ``root``: the package folder (default: this package's).  About 1 MB read once
    per process.
    """
    if root is None:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    digest = hashlib.sha256()
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            digest.update(os.path.relpath(path, root).replace(os.sep, "/").encode() + b"\0")
            with open(path, "rb") as f:
                digest.update(f.read() + b"\0")
    return digest.hexdigest()[:16]


def compiled(function=None, signature=None, **options):
    """``numba.njit(cache=True, **options)`` with :func:`cache_dir` as numba's cache directory.

    numba picks a function's cache directory when it is decorated, so the
    directory is set for this decoration only and other numba users of the
    process keep theirs.  ``@compiled`` or ``@compiled(error_model="numpy", ...)``.
    With a ``signature`` the kernel is compiled (or loaded) when it is decorated
    and takes no other argument types: the dispatcher refuses them (TypeError)
    instead of compiling another specialisation.
    """
    if function is None:
        return lambda f: compiled(f, signature, **options)
    jit = (lambda **kw: numba.njit(**kw)) if signature is None else (
        lambda **kw: numba.njit(signature, **kw))
    saved = numba_config.CACHE_DIR
    numba_config.CACHE_DIR = cache_dir()
    try:
        return jit(cache=True, **options)(function)
    except RuntimeError as exc:  # numba: "cannot cache function ...: no locator available"
        log.warning("compiled kernels: no writable cache directory (%s); compiling at every "
                    "start", exc)
        return jit(**options)(function)
    finally:
        numba_config.CACHE_DIR = saved


@numba.njit(inline="always")
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@numba.njit(inline="always")
def _mat_vec(M, v, out):
    for i in range(3):
        out[i] = M[i, 0] * v[0] + M[i, 1] * v[1] + M[i, 2] * v[2]


@compiled
def chain_tensors(q, qd, A, B, C, axes, revolute, frame, dirs, moves, known, prismatic,
                  z_index, perp_index, has_w0):
    """(H, dH, dH_rate, W, W_rate) of a chain: ``KinematicRegressor.tensors_numpy`` compiled.

    Parameters are the regressor's constant arrays (see ``KinematicRegressor``):
    A, B, C (n, 3, 3) of M_k = A + sin q_k B + (1 - cos q_k) C, axes (n, 3),
    revolute (n,) 1.0/0.0, frame (S,) int, dirs (S, 3), moves (n, S) 1.0/0.0,
    known (m, S), prismatic (P, 2) int rows (joint, direction), z_index
    (m, p_z) and perp_index (2m, p_perp) the entries (3 row + coordinate) of
    the table that H and W read, has_w0 bool.
    """
    n = q.shape[0]
    S = frame.shape[0]
    m = known.shape[0]
    w0 = S
    one = S + (m if has_w0 else 0)
    rows = one + 2
    # the frame recursion R_{k+1} = R_k M_k(q_k)
    R = np.zeros((n + 1, 3, 3))
    for i in range(3):
        R[0, i, i] = 1.0
    Mk = np.empty((3, 3))
    for k in range(n):
        s, c = math.sin(q[k]), 1.0 - math.cos(q[k])
        for i in range(3):
            for j in range(3):
                Mk[i, j] = A[k, i, j] + s * B[k, i, j] + c * C[k, i, j]
        for i in range(3):
            for j in range(3):
                R[k + 1, i, j] = (R[k, i, 0] * Mk[0, j] + R[k, i, 1] * Mk[1, j]
                                  + R[k, i, 2] * Mk[2, j])
    # omega_l (world axes), the frames' angular velocities Omega and omega_l_dot
    ax = np.empty((n, 3))
    Omega = np.zeros((n + 1, 3))
    ax_dot = np.empty((n, 3))
    for k in range(n):
        _mat_vec(R[k], axes[k], ax[k])
        w = qd[k] * revolute[k]
        for i in range(3):
            Omega[k + 1, i] = Omega[k, i] + w * ax[k, i]
    for k in range(n):
        _cross(Omega[k], ax[k], ax_dot[k])
    # the table: value, joint gradient and its rate of every row (see _evaluate)
    T = np.zeros((rows, 3))
    dT = np.zeros((n, rows, 3))
    dTr = np.zeros((n, rows, 3))
    V_dot = np.empty((S, 3))
    t1 = np.empty(3)
    t2 = np.empty(3)
    for s in range(S):
        _mat_vec(R[frame[s]], dirs[s], T[s])
        _cross(Omega[frame[s]], T[s], V_dot[s])
        for k in range(n):
            if moves[k, s] != 0.0:
                _cross(ax[k], T[s], dT[k, s])
                _cross(ax_dot[k], T[s], t1)
                _cross(ax[k], V_dot[s], t2)
                for i in range(3):
                    dTr[k, s, i] = t1[i] + t2[i]
    if has_w0:
        coef = known.copy()
        coef_rate = np.zeros((m, S))
        for p in range(prismatic.shape[0]):
            k, s = prismatic[p, 0], prismatic[p, 1]
            for i in range(m):
                coef[i, s] += q[k]
                coef_rate[i, s] += qd[k]
        for i in range(m):
            for c3 in range(3):
                acc = 0.0
                for s in range(S):
                    acc += coef[i, s] * T[s, c3]
                T[w0 + i, c3] = acc
            for k in range(n):
                for c3 in range(3):
                    acc, acc_rate, acc_cross = 0.0, 0.0, 0.0
                    for s in range(S):
                        acc += dT[k, s, c3] * coef[i, s]
                        acc_rate += dTr[k, s, c3] * coef[i, s]
                        acc_cross += dT[k, s, c3] * coef_rate[i, s]
                    dT[k, w0 + i, c3] = acc
                    dTr[k, w0 + i, c3] = acc_rate + acc_cross
        for p in range(prismatic.shape[0]):
            k, s = prismatic[p, 0], prismatic[p, 1]
            for i in range(m):
                for c3 in range(3):
                    dT[k, w0 + i, c3] += T[s, c3]
                    dTr[k, w0 + i, c3] += V_dot[s, c3]
    for c3 in range(3):
        T[one, c3] = 1.0
    # the gather of _assemble: every entry reads one entry (row * 3 + coordinate) of the
    # table; loops ordered so that the innermost one writes contiguously
    T = T.reshape(rows * 3)
    dT = dT.reshape(n, rows * 3)
    dTr = dTr.reshape(n, rows * 3)
    p_z = z_index.shape[1]
    H = np.empty((m, p_z))
    dH = np.empty((m, n, p_z))
    dH_rate = np.empty((m, n, p_z))
    for i in range(m):
        for p in range(p_z):
            H[i, p] = T[z_index[i, p]]
        for k in range(n):
            for p in range(p_z):
                dH[i, k, p] = dT[k, z_index[i, p]]
                dH_rate[i, k, p] = dTr[k, z_index[i, p]]
    rows2, p_perp = perp_index.shape
    W = np.empty((rows2, n, p_perp))
    W_rate = np.empty((rows2, n, p_perp))
    for i in range(rows2):
        for k in range(n):
            for p in range(p_perp):
                W[i, k, p] = dT[k, perp_index[i, p]]
                W_rate[i, k, p] = dTr[k, perp_index[i, p]]
    return H, dH, dH_rate, W, W_rate


@compiled
def paper_tensors(q, qd):
    """(H, dH, dH_rate, W, W_rate) of the paper's arm: ``kinematic_tensors_numpy`` compiled."""
    q1, q2, q3 = q[0], q[1], q[2]
    w1, w2, w3 = qd[0], qd[1], qd[2]
    s1, c1, s2, c2 = math.sin(q1), math.cos(q1), math.sin(q2), math.cos(q2)
    s23, c23 = math.sin(q2 + q3), math.cos(q2 + q3)
    w23 = w2 + w3
    c1c2, c1c23, c1s2, c1s23 = c1 * c2, c1 * c23, c1 * s2, c1 * s23
    s1c2, s1c23, s1s2, s1s23 = s1 * c2, s1 * c23, s1 * s2, s1 * s23
    H = np.empty((1, 3))
    H[0, 0], H[0, 1], H[0, 2] = c1c2, c1c23, 1.0
    dH = np.zeros((1, 3, 3))
    dH[0, 0, 0], dH[0, 0, 1] = -s1c2, -s1c23
    dH[0, 1, 0], dH[0, 1, 1] = -c1s2, -c1s23
    dH[0, 2, 1] = -c1s23
    dH_rate = np.zeros((1, 3, 3))
    dH_rate[0, 0, 0] = -c1c2 * w1 + s1s2 * w2
    dH_rate[0, 0, 1] = -c1c23 * w1 + s1s23 * w23
    dH_rate[0, 1, 0] = s1s2 * w1 - c1c2 * w2
    dH_rate[0, 1, 1] = s1s23 * w1 - c1c23 * w23
    dH_rate[0, 2, 1] = s1s23 * w1 - c1c23 * w23
    W = np.zeros((2, 3, 2))
    W[0, 0, 0], W[0, 0, 1] = c1c2, c1c23
    W[0, 1, 0], W[0, 1, 1] = -s1s2, -s1s23
    W[0, 2, 1] = -s1s23
    W[1, 1, 0], W[1, 1, 1] = c2, c23
    W[1, 2, 1] = c23
    W_rate = np.zeros((2, 3, 2))
    W_rate[0, 0, 0] = -s1c2 * w1 - c1s2 * w2
    W_rate[0, 0, 1] = -s1c23 * w1 - c1s23 * w23
    W_rate[0, 1, 0] = -c1s2 * w1 - s1c2 * w2
    W_rate[0, 1, 1] = -c1s23 * w1 - s1c23 * w23
    W_rate[0, 2, 1] = -c1s23 * w1 - s1c23 * w23
    W_rate[1, 1, 0] = -s2 * w2
    W_rate[1, 1, 1] = -s23 * w23
    W_rate[1, 2, 1] = -s23 * w23
    return H, dH, dH_rate, W, W_rate
