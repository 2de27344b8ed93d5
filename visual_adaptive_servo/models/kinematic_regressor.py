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

"""Property 1 for any serial chain: kinematic regressors that need no length and no camera.

Write feature point i as a sum over the chain's unknown lengths theta_k (joint
origin translation components and tip-frame offset components)::

    r_i(q) = w0_i(q) + sum_k theta_k v_k(q),      v_k(q) = R_f(k)(q) d_k

where ``R_f`` is the rotation of a chain frame (it depends on q and on known
structure only: joint axes and origin rotations), ``d_k`` a constant unit
direction in that frame, and ``w0_i`` gathers what is known (lengths declared
known, and q_k times the axis of each prismatic joint).  The camera's
projection matrix P = [[D_bar, d_bar0], [d3^T, d0]] (pixels of the controller,
depth in metres) then gives

    z_i     = d3^T r_i + d0     : linear in the products d3_l theta_k, d3_l, d0   -> a_z
    J_z_perp = D_bar dr/dq      : linear in the products D_bar_ab theta_k, D_bar_ab -> a_z_perp

The image offset d_bar0 never appears in J (eq (a1)).  Many of these products
are not independent as functions of q: a length in the base frame gives a
constant depth term (it folds into d0) and no Jacobian term; two lengths along
the same direction of the same frame act as one.  The full set of columns is
therefore reduced to an independent basis once, numerically: the column
functions are sampled at random configurations, a QR with column pivoting
picks independent columns B, and least squares gives E with
``full_columns(q) = full_columns(q)[:, B] @ E`` for every sample (checked to
1e-9).  The controller adapts ``a = E a_full``; only the B columns are
evaluated at run time.

Derivatives are exact and closed-form: with omega_l the world axis of revolute
joint l, ``dv/dq_l = omega_l x v`` for the joints before the vector's frame,
and along a motion ``d/dt (omega_l x v) = omega_l_dot x v + omega_l x v_dot``
with ``v_dot = Omega_f x v`` (Omega_f the angular velocity of frame f) and
``omega_l_dot = Omega_l x omega_l``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .backend import compile_notice, kernels, resolve_backend
from .urdf_chain import skew

AXES = "xyz"
_SAMPLES = 64
_RANK_TOL = 1e-10
_RESIDUAL_TOL = 1e-9


@dataclass(frozen=True)
class Length:
    """One length of the chain: ``theta v(q)`` with ``v = R_frame(q) direction``."""

    name: str
    frame: int
    direction: np.ndarray
    points: tuple
    value: float
    unknown: bool


@dataclass(frozen=True)
class Reduction:
    """An independent basis of column functions: full columns = basis columns @ E."""

    basis: np.ndarray       # (p,) indices into the full columns
    E: np.ndarray           # (p, p_full)
    labels: tuple
    full_labels: tuple


# (v @ _SKEW).reshape(3, 3) is the cross-product matrix [v]x (one product for many vectors)
_SKEW = np.zeros((3, 9))
_SKEW[2, 1], _SKEW[1, 2], _SKEW[2, 3] = -1.0, 1.0, 1.0
_SKEW[0, 5], _SKEW[1, 6], _SKEW[0, 7] = -1.0, -1.0, 1.0
# symbolic table rows of the columns: the known part w0_i (one row per point) and the constant 1
_W0, _ONE = -1, -2


class KinematicRegressor:
    """The tensors H, dH, W and their rates (see :class:`~.base.RobotCameraModel`) of a chain.

    Parameters
    ----------
    chain : urdf_chain.KinematicChain
    offsets : (m, 3)
        Nominal feature offsets c_i in the tip frame [m] (m = 1, 2 or 3).
    unknown : "all" or sequence of str
        Names of the unknown lengths (see :attr:`length_names`); the others are
        taken as known, at their nominal values.
    backend : {"compiled", "numpy"}, optional
        What :meth:`tensors` runs: the numba kernel
        (:func:`.kernels.chain_tensors`) or :meth:`tensors_numpy`, the
        reference; default compiled when numba imports (:mod:`.backend`).
    """

    def __init__(self, chain, offsets, unknown="all", backend=None):
        self.chain = chain
        self.offsets = np.array(offsets, dtype=float).reshape(-1, 3)
        self.n, self.m = chain.n, len(self.offsets)
        self.lengths = self._lengths(unknown)
        self._structure()
        self._columns()
        z_samples, perp_samples = self._full_samples()
        self.z_reduction = self._reduce(z_samples, self.z_full_labels)
        self.perp_reduction = self._reduce(perp_samples, self.perp_full_labels)
        self._gather()
        self.set_backend(backend)

    # -- structure -----------------------------------------------------------------
    def _lengths(self, unknown):
        chain, lengths = self.chain, []
        everything = []
        for k, joint in enumerate(chain.joints):
            for j in range(3):
                if joint.origin_translation[j] != 0.0:
                    everything.append((f"{joint.name}.{AXES[j]}", k, np.eye(3)[j],
                                       tuple(range(self.m)), joint.origin_translation[j]))
        tip_name = chain.tip_joints[-1] if chain.tip_joints else chain.tip_link
        for j in range(3):
            if chain.tip_translation[j] != 0.0:
                everything.append((f"{tip_name}.{AXES[j]}", chain.n, np.eye(3)[j],
                                   tuple(range(self.m)), chain.tip_translation[j]))
        for i, c in enumerate(self.offsets):
            for j in range(3):
                everything.append((f"point{i + 1}.{AXES[j]}", chain.n,
                                   chain.tip_rotation[:, j], (i,), c[j]))
        names = [e[0] for e in everything]
        joint_names = {joint.name for joint in chain.joints} | {tip_name}
        if isinstance(unknown, str):
            if unknown != "all":
                raise ValueError(f"unknown_lengths: 'all' or a list of names, got {unknown!r}")
            chosen = set(names)
        else:
            chosen = set(unknown)
            missing = sorted(chosen - set(names))
            if missing:
                # a joint's origin component that is 0 in the URDF is no length of the chain
                zero = [name for name in missing if "." in name
                        and name.rsplit(".", 1)[0] in joint_names and name[-1] in AXES]
                why = (f" ({', '.join(zero)}: 0 in the URDF's joint origin, so not a length)"
                       if zero else "")
                raise ValueError(f"unknown_lengths: no length(s) {missing} in this chain"
                                 f"{why}; known names: {names}")
        for name, frame, direction, points, value in everything:
            lengths.append(Length(name, frame, direction, points, float(value), name in chosen))
        return tuple(lengths)

    @property
    def length_names(self):
        return tuple(L.name for L in self.lengths)

    def _structure(self):
        """Directions table, prismatic terms and the constant arrays of the frame recursion."""
        chain, n = self.chain, self.n
        keys = []

        def key_index(frame, direction):
            for s, (f, d) in enumerate(keys):
                if f == frame and np.allclose(d, direction, atol=1e-12):
                    return s
            keys.append((frame, np.asarray(direction, dtype=float)))
            return len(keys) - 1

        self._length_dir = [key_index(L.frame, L.direction) for L in self.lengths]
        self._prismatic = [(k, key_index(k, j.origin_rotation @ j.axis))
                           for k, j in enumerate(chain.joints) if j.prismatic]
        self.S = len(keys)
        self._frame = np.array([f for f, _ in keys], dtype=int)
        self._dirs = np.array([d for _, d in keys])
        # M_k(q_k) = R_o Rot(axis, q_k) = A + sin q_k B + (1 - cos q_k) C  (B = C = 0: prismatic)
        self._A = np.array([j.origin_rotation for j in chain.joints])
        K = np.array([np.zeros((3, 3)) if j.prismatic else skew(j.axis) for j in chain.joints])
        self._B = self._A @ K
        self._C = self._A @ K @ K
        self._axes = np.array([j.origin_rotation @ j.axis for j in chain.joints])
        self._revolute = np.array([not j.prismatic for j in chain.joints], dtype=float)
        # dv_s/dq_l = omega_l x v_s for revolute joints l before frame f_s, as (n, 1, S)
        self._moves = ((np.arange(n)[:, None] < self._frame[None, :])
                       * self._revolute[:, None])[:, None, :]
        # known part w0_i: constant coefficients of the known lengths, per point
        self._known = np.zeros((self.m, self.S))
        for L, s in zip(self.lengths, self._length_dir):
            if not L.unknown:
                self._known[list(L.points), s] += L.value
        self.has_w0 = bool(self._prismatic) or bool(np.any(self._known))

    # -- evaluation ------------------------------------------------------------------
    def _evaluate(self, q, qd):
        """Value, joint gradient and its rate of every column vector: the lookup table.

        Returns V (R, 3), dV and dV_rate (n, 3, R) with R rows: the S directions
        v_s, then (when there is a known part) w0_i of each point, then the
        constant 1, then 0 (what a column reads for a point it does not
        involve).  ``dV[l, :, r]`` is the derivative of row r by q_l.
        """
        n, S = self.n, self.S
        sin_q, cos_q = np.sin(q), np.cos(q)
        M = self._A + sin_q[:, None, None] * self._B + (1.0 - cos_q)[:, None, None] * self._C
        R = np.empty((n + 1, 3, 3))
        R[0] = np.eye(3)
        for k in range(n):
            R[k + 1] = R[k].dot(M[k])
        axes = (R[:n] @ self._axes[:, :, None])[:, :, 0]           # omega_l (or prismatic u_l)
        Omega = np.zeros((n + 1, 3))
        Omega[1:] = np.cumsum((qd * self._revolute)[:, None] * axes, axis=0)
        skews = (np.vstack([axes, Omega]) @ _SKEW).reshape(-1, 3, 3)
        axes_x, Omega_x = skews[:n], skews[n:]
        axes_dot_x = ((Omega_x[:n] @ axes[:, :, None])[:, :, 0] @ _SKEW).reshape(n, 3, 3)
        V = (R[self._frame] @ self._dirs[:, :, None])[:, :, 0]    # (S, 3)
        V_dot = (Omega_x[self._frame] @ V[:, :, None])[:, :, 0]   # Omega_f x v
        dV = (axes_x @ V.T) * self._moves                           # (n, 3, S)
        dV_rate = (axes_dot_x @ V.T + axes_x @ V_dot.T) * self._moves
        if not self.has_w0:
            return (np.vstack([V, self._last_rows]),
                    np.concatenate([dV, self._zero_cols], axis=2),
                    np.concatenate([dV_rate, self._zero_cols], axis=2))
        coef, coef_rate = self._known.copy(), np.zeros((self.m, S))
        for k, s in self._prismatic:
            coef[:, s] += q[k]
            coef_rate[:, s] += qd[k]
        dW0 = dV @ coef.T                                            # (n, 3, m)
        dW0_rate = dV_rate @ coef.T + dV @ coef_rate.T
        for k, s in self._prismatic:
            dW0[k] += V[s][:, None]
            dW0_rate[k] += V_dot[s][:, None]
        return (np.vstack([V, coef @ V, self._last_rows]),
                np.concatenate([dV, dW0, self._zero_cols], axis=2),
                np.concatenate([dV_rate, dW0_rate, self._zero_cols], axis=2))

    # -- the full columns and their reduction --------------------------------------------
    def _columns(self):
        m = self.m
        z_cols, perp_cols = [], []   # (table row, coordinate, point mask, label, tag)
        for L, s in zip(self.lengths, self._length_dir):
            if not L.unknown:
                continue
            mask = np.isin(np.arange(m), L.points).astype(float)
            for c in range(3):
                z_cols.append((s, c, mask, f"d3{AXES[c]}*{L.name}", ("len", L, c)))
            for a in range(2):
                for b in range(3):
                    perp_cols.append((s, (a, b), mask, f"D{a + 1}{AXES[b]}*{L.name}",
                                      ("len", L, a, b)))
        if self.has_w0:
            ones = np.ones(m)
            for c in range(3):
                z_cols.append((_W0, c, ones, f"d3{AXES[c]}*known", ("w0", c)))
            for a in range(2):
                for b in range(3):
                    perp_cols.append((_W0, (a, b), ones, f"D{a + 1}{AXES[b]}*known",
                                      ("w0", a, b)))
        z_cols.append((_ONE, 0, np.ones(m), "d0", ("d0",)))
        self._z_cols, self._perp_cols = z_cols, perp_cols
        self.z_full_labels = tuple(c[3] for c in z_cols)
        self.perp_full_labels = tuple(c[3] for c in perp_cols)
        self._last_rows = np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])   # the 1 and the 0
        self._zero_cols = np.zeros((self.n, 3, 2))

    def _indices(self, columns):
        """Table row and coordinate of every (point, column) entry of H, (m, p) each.

        An entry of a point the column does not involve reads the zero row, so the
        gather itself yields H, dH and their rates (no mask to multiply).
        """
        m, S = self.m, self.S
        one = S + (m if self.has_w0 else 0)
        rows = np.empty((m, len(columns)), dtype=int)
        coords = np.empty((m, len(columns)), dtype=int)
        for p, col in enumerate(columns):
            row, coord, mask = col[0], col[1], col[2]
            rows[:, p] = (S + np.arange(m) if row == _W0 else one if row == _ONE else row)
            coords[:, p] = coord[1] if isinstance(coord, tuple) else coord
            rows[mask == 0.0, p] = one + 1
        return rows, coords

    def _perp_gather(self, columns):
        """Table row and coordinate of every (image row, column) entry of W, (2m, p) each.

        Column (a, b) of point i has entries only in image row 2i + a; the rest read 0.
        """
        rows, comps = self._indices(columns)
        image_row = np.array([c[1][0] for c in columns], dtype=int)
        zero = self.S + (self.m if self.has_w0 else 0) + 1
        wrows = np.repeat(rows, 2, axis=0)
        wrows[np.arange(2 * self.m)[:, None] % 2 != image_row[None, :]] = zero
        return wrows, np.repeat(comps, 2, axis=0)

    def _assemble(self, table, z_index, perp_index):
        """(H, dH, dH_rate, W, W_rate) of the columns ``z_index``/``perp_index`` from the table."""
        V, dV, dV_rate = table
        zr, zc = z_index
        pr, pc = perp_index
        return (V[zr, zc], dV[:, zc, zr].transpose(1, 0, 2),
                dV_rate[:, zc, zr].transpose(1, 0, 2), dV[:, pc, pr].transpose(1, 0, 2),
                dV_rate[:, pc, pr].transpose(1, 0, 2))

    def _sample_configurations(self):
        rng = np.random.default_rng(0)
        lo = np.where(self._revolute > 0, -np.pi, -1.0)
        return rng.uniform(lo, -lo, size=(_SAMPLES, self.n))

    def _full_samples(self):
        """Every full column function at the sample configurations (H and W stacked by rows)."""
        z_index, perp_index = self._indices(self._z_cols), self._perp_gather(self._perp_cols)
        z_rows, perp_rows = [], []
        for q in self._sample_configurations():
            H, _, _, W, _ = self._assemble(self._evaluate(q, np.zeros(self.n)), z_index,
                                           perp_index)
            z_rows.append(H)
            perp_rows.append(W.reshape(-1, W.shape[-1]))
        return np.vstack(z_rows), np.vstack(perp_rows)

    @property
    def _z_samples(self):
        return self._full_samples()[0]

    @property
    def _perp_samples(self):
        return self._full_samples()[1]

    @staticmethod
    def _reduce(samples, labels):
        from scipy.linalg import qr

        if samples.shape[1] == 0:
            return Reduction(np.zeros(0, dtype=int), np.zeros((0, 0)), (), tuple(labels))
        scale = np.max(np.abs(samples))
        if scale == 0.0:
            return Reduction(np.zeros(0, dtype=int), np.zeros((0, samples.shape[1])), (),
                             tuple(labels))
        _, r, pivots = qr(samples / scale, mode="economic", pivoting=True)
        diag = np.abs(np.diag(r))
        rank = int(np.count_nonzero(diag > _RANK_TOL * max(samples.shape) * diag[0]))
        basis = np.sort(pivots[:rank])
        E, *_ = np.linalg.lstsq(samples[:, basis], samples, rcond=None)
        residual = np.max(np.abs(samples[:, basis] @ E - samples))
        if residual > _RESIDUAL_TOL * scale:
            raise ArithmeticError(f"kinematic regressor reduction: residual {residual:.3g} "
                                  f"(scale {scale:.3g}); the column functions could not be "
                                  f"reduced to an exact basis")
        names = []
        for row, b in zip(E, basis):
            # E is kept whole (URDFs' rounded pi/2 give true entries ~1e-12); labels
            # mention only the combinations that matter
            others = int(np.count_nonzero(np.abs(row) > 1e-9)) - 1
            names.append(labels[b] + (f"+{others} more" if others > 0 else ""))
        return Reduction(basis, E, tuple(names), tuple(labels))

    def _gather(self):
        zb, pb = self.z_reduction.basis, self.perp_reduction.basis
        self._z_index = self._indices([self._z_cols[b] for b in zb])
        self._perp_index = self._perp_gather([self._perp_cols[b] for b in pb])
        self.p_z, self.p_perp = len(zb), len(pb)

    def set_backend(self, backend):
        """Run :meth:`tensors` on ``backend`` from now on (None: compiled when numba imports).

        Choosing compiled compiles the kernel (or loads it from numba's cache)
        here, rather than in the first control period.
        """
        backend = resolve_backend(backend)
        if backend == "compiled":
            with compile_notice("kinematic tensors"):
                self._kernel_arguments()
        self.backend = backend

    def _kernel_arguments(self):
        """The constant arrays of :func:`.kernels.chain_tensors`, and its first call."""
        index = np.intp
        self._kernel = kernels().chain_tensors
        self._kernel_constants = (
            np.ascontiguousarray(self._A), np.ascontiguousarray(self._B),
            np.ascontiguousarray(self._C), np.ascontiguousarray(self._axes),
            np.ascontiguousarray(self._revolute), self._frame.astype(index),
            np.ascontiguousarray(self._dirs, dtype=float),
            np.ascontiguousarray(self._moves[:, 0, :], dtype=float),
            np.ascontiguousarray(self._known),
            np.array(self._prismatic, dtype=index).reshape(-1, 2),
            (3 * self._z_index[0] + self._z_index[1]).astype(index),
            (3 * self._perp_index[0] + self._perp_index[1]).astype(index), self.has_w0)
        zero = np.zeros(self.n)
        self._kernel(zero, zero, *self._kernel_constants)

    # -- public ----------------------------------------------------------------------
    def tensors(self, q, qd):
        """``(H, dH, dH_rate, W, W_rate)`` at (q, q_dot): shapes as in RobotCameraModel.

        Runs the backend chosen at construction; :meth:`tensors_numpy` is the reference.
        """
        if self.backend == "numpy":
            return self.tensors_numpy(q, qd)
        # contiguous float64, so that no call compiles another specialisation; the kernel
        # does not check bounds, so the shapes are checked here
        q = np.ascontiguousarray(q, dtype=float)
        qd = np.ascontiguousarray(qd, dtype=float)
        if q.shape != (self.n,) or qd.shape != (self.n,):
            raise ValueError(f"kinematic tensors: q and q_dot need shape ({self.n},), got "
                             f"{q.shape} and {qd.shape}")
        return self._kernel(q, qd, *self._kernel_constants)

    def tensors_numpy(self, q, qd):
        """:meth:`tensors` in numpy: the readable reference of the compiled kernel."""
        table = self._evaluate(np.asarray(q, dtype=float), np.asarray(qd, dtype=float))
        return self._assemble(table, self._z_index, self._perp_index)

    def parameters(self, camera_matrix, lengths=None):
        """(a_z_perp, a_z) of this chain seen through ``camera_matrix``.

        Parameters
        ----------
        camera_matrix : (3, 4)
            P = [[D_bar, d_bar0], [d3^T, d0]] in the base frame of the chain, mapping
            homogeneous points to (pixels * depth, depth) in the controller's pixels.
        lengths : dict, optional
            Values of the unknown lengths by name; default: their nominal values.
        """
        P = np.asarray(camera_matrix, dtype=float)
        D_bar, d3, d0 = P[:2, :3], P[2, :3], P[2, 3]
        values = {L.name: L.value for L in self.lengths}
        if lengths:
            unknown = set(lengths) - set(values)
            if unknown:
                raise ValueError(f"lengths: no length(s) {sorted(unknown)} in this chain")
            values.update(lengths)
        z_full = np.array([d3[c[4][2]] * values[c[4][1].name] if c[4][0] == "len"
                           else d3[c[4][1]] if c[4][0] == "w0" else d0 for c in self._z_cols])
        perp_full = np.array([D_bar[c[4][2], c[4][3]] * values[c[4][1].name] if c[4][0] == "len"
                              else D_bar[c[4][1], c[4][2]] for c in self._perp_cols])
        return self.perp_reduction.E @ perp_full, self.z_reduction.E @ z_full
