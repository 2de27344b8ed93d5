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

"""Whether the camera's image motion runs against the model's: a mirrored guess, said early.

A guessed camera with a pixel axis the wrong way (``pixel_axes``, ``pixel_origin``),
placed on the far side of the arm, or turned by more than 90 degrees about its axis
predicts image motion that the real camera shows reversed along the directions the
points move.  The loop then pushes the points the wrong way, and neither eqs (23)-(25)
nor the image-motion scale (a positive number) turn that around: the iiwa with one pixel
axis of its guess turned diverges within 0.4-0.6 s, a 5-joint arm with its guessed camera
on the far side within 0.5 s.  This is what the frames can tell before that.

At frames (at most one every ``interval`` s) it fits one slope b of the frames on the
model's image path P(t) (:class:`~.motion_scale.MotionScale`'s, the joints' motion through
the estimated model), every image coordinate about its own mean, pooled, over an
exponentially weighted window -- the scale's own regression, unbounded:

    x_c,j - mean_j = b (P_j(t_c) - mean_j) + residual,    j = 1..2m.

With the truth's image motion A times the model's (2 x 2, per point), b is a weighted mean
of p^T A p / p^T p over the path's motions p.  For a guess off by a scale, a stretch along
the image axes or a turn of less than 90 degrees about the optical axis, p^T A p > 0 for
every p: b > 0, the image moves the model's way, and the adaptation has something to
mend.  b < 0 says the image moved against the model along the path the points took: along
it the loop pushes them the wrong way.  The verdict needs b below zero by
``significance`` times its standard error, from the fit's own residual (the noise and
whatever else the model gets wrong), with the window's weight as the number of frames, and
at least ``MIN_FRAMES`` of them.

It is a diagnosis, not a stop.  A guess whose a_z_perp is far off relative to a_z also
moves the image against the model along the start's path, and that one the image-motion
ratio (``motion_scale.ratio_rate``) mends: two of 100 draws of the iiwa's real-camera campaign
(a_z_perp x0.74 and x0.65 against a_z x1.81 and x1.75) got a verdict at 0.7-0.8 s, with
slopes of -1.25 and -2.61, and end at 0.22 and 0.43 px.  Stopping there would have
stopped two runs that track; the 2 x 2 map of the frames' motion on the model's has a
negative determinant there too, so no reflection test tells them from a mirrored camera
at that time.  So the first verdict is logged (a warning) and kept
(``AdaptiveVisualTracker.reversed_motion``), and a run that diverges says it in its
reason, which then points at the guessed camera instead of only at the estimate that
grew first.
"""

from __future__ import annotations

from math import exp, sqrt

import numpy as np

#: frames (their weight) before any verdict
MIN_FRAMES = 10.0


class ReversedMotion:
    """The slope of the frames' motion on the model's, and its verdict (module docstring).

    Parameters
    ----------
    window : float
        Time constant of the frames' weighting [s].
    significance : float
        How many standard errors below zero b must be.
    interval : float
        Frames closer than this to the last one fitted are skipped [s].
    """

    def __init__(self, window, significance, interval=0.02):
        self.window = float(window)
        self.significance = float(significance)
        self.interval = float(interval)
        self.reset()

    def reset(self):
        self.weight = 0.0
        self.t_frame = None
        self.sums = None        # weighted sums of x, p, x p, p^2, x^2, per coordinate (5, 2m)
        self.fit = None         # (b, its standard error) at the last frame with a fit

    def due(self, stamp):
        """Whether a frame captured at ``stamp`` would be fitted (``interval`` after the last)."""
        return self.t_frame is None or stamp >= self.t_frame + self.interval

    def frame(self, stamp, x, p):
        """Add a frame (pixels x (2m,), the model path p (2m,) at its capture time).

        Returns the verdict's text when the frames move against the model, else None.
        """
        if not self.due(stamp):
            return None
        x = np.asarray(x, dtype=float)
        p = np.asarray(p, dtype=float)
        terms = np.stack([x, p, x * p, p * p, x * x])
        if self.sums is None:
            self.sums, self.weight = terms, 1.0
        else:
            decay = exp(-(stamp - self.t_frame) / self.window)
            self.sums = decay * self.sums + terms
            self.weight = decay * self.weight + 1.0
        self.t_frame = stamp
        return self._verdict()

    def _verdict(self):
        w = self.weight
        if w < MIN_FRAMES:
            return None
        sx, sp, sxp, spp, sxx = self.sums / w
        var_p = float(np.sum(spp - sp * sp))
        if not var_p > 0.0:
            return None
        cov = float(np.sum(sxp - sx * sp))
        var_x = float(np.sum(sxx - sx * sx))
        b = cov / var_p
        # the residual's variance per coordinate and frame; b's standard error
        residual = max(var_x - b * cov, 0.0) / sx.size
        error = sqrt(residual / (w * var_p))
        self.fit = (b, error)
        if not -b > self.significance * error:
            return None
        return (f"the frames move against the model's image motion (their slope on the "
                f"model's path is {b:.3g} +- {error:.2g} over {w:.0f} frames; a guess the "
                f"adaptation can mend gives a positive one): the guessed camera sees the "
                f"image mirrored or turned past 90 deg, or a_z_perp is far off relative to "
                f"a_z (the image-motion ratio mends that within a second or two) -- if the "
                f"run does not recover, check initial_estimate.camera's pixel_axes and "
                f"pixel_origin against your camera's pixels, and that it is on the side of "
                f"the arm the real camera is and looks the same way up (reversed_motion)")
