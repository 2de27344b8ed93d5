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

"""The numbers of timeseries.csv formatted by compiled code, exactly as Python's ``"%.10g"``.

Python formats a float in ~0.2-0.8 µs; a 1 kHz run of the iiwa has 195
columns, so writing its CSV cost more than the run's control.  Here each
number is rounded to 10 significant digits in float arithmetic:
``a * 10**(9 - e)`` (10**k the correctly rounded double, the product
rounded once) carries a relative error below 3e-16, i.e. below 3e-6 of
the last digit, so wherever the dropped part is more than 1e-4 away from one
half the rounding is certainly the correctly rounded one Python makes.  The
few numbers closer to a tie (and those beyond 1e+-290) are marked and
formatted by Python (:func:`recorder.write_csv` does that).  The text follows
Python's ``g`` rules: fixed notation for exponents -4..9, else ``d.ddde+XX``,
trailing zeros and a bare point removed, ``nan``, ``inf``, ``-0``.
"""

from __future__ import annotations

import math

import numpy as np

from ..models.kernels import compiled

#: bytes per formatted number, at most ("-1.234567891e-100" has 17)
WIDTH = 24
_TIE_MARGIN = 1e-4
#: 10**k for k = 0..309, each the correctly rounded double (exact up to 10**22)
_POW10 = np.array([float(f"1e{k}") for k in range(310)])


@compiled
def format_g10(values, text, lengths, undecided):
    """``"%.10g" % v`` of every v in ``values`` (N,) as ASCII into ``text`` (N, WIDTH) uint8.

    ``lengths`` (N,) gets each text's length; ``undecided`` (N,) bool marks
    the numbers left to Python (near a rounding tie or of magnitude outside
    1e-290..1e290), whose text is not written.
    """
    digits = np.empty(10, dtype=np.uint8)
    for i in range(values.shape[0]):
        v = values[i]
        out = text[i]
        at = 0
        undecided[i] = False
        if math.isnan(v):
            out[0], out[1], out[2] = 110, 97, 110          # nan
            lengths[i] = 3
            continue
        if v < 0.0 or (v == 0.0 and math.copysign(1.0, v) < 0.0):
            out[0] = 45                                      # -
            at = 1
        a = abs(v)
        if math.isinf(a):
            out[at], out[at + 1], out[at + 2] = 105, 110, 102  # inf
            lengths[i] = at + 3
            continue
        if a == 0.0:
            out[at] = 48
            lengths[i] = at + 1
            continue
        if a < 1e-290 or a > 1e290:
            undecided[i] = True
            continue
        # the decimal exponent from the binary one (log10(2) = 0.30103), corrected below
        e = int(math.floor(math.frexp(a)[1] * 0.30102999566398120))
        scaled = 0.0
        for _ in range(4):
            k = 9 - e
            scaled = a * _POW10[k] if k >= 0 else a / _POW10[-k]
            if scaled >= 1e10:
                e += 1
            elif scaled < 1e9:
                e -= 1
            else:
                break
        if not 1e9 <= scaled < 1e10:
            undecided[i] = True
            continue
        whole = math.floor(scaled)
        frac = scaled - whole
        if abs(frac - 0.5) < _TIE_MARGIN:
            undecided[i] = True
            continue
        n = int(whole) + (1 if frac > 0.5 else 0)
        if n >= 10000000000:
            n //= 10
            e += 1
        for j in range(9, -1, -1):
            digits[j] = 48 + n % 10
            n //= 10
        last = 9
        while last > 0 and digits[last] == 48:
            last -= 1
        if -4 <= e < 10:
            if e >= 0:
                for j in range(e + 1):
                    out[at] = digits[j]
                    at += 1
                if last > e:
                    out[at] = 46                             # .
                    at += 1
                    for j in range(e + 1, last + 1):
                        out[at] = digits[j]
                        at += 1
            else:
                out[at], out[at + 1] = 48, 46                # 0.
                at += 2
                for _ in range(-e - 1):
                    out[at] = 48
                    at += 1
                for j in range(last + 1):
                    out[at] = digits[j]
                    at += 1
        else:
            out[at] = digits[0]
            at += 1
            if last > 0:
                out[at] = 46
                at += 1
                for j in range(1, last + 1):
                    out[at] = digits[j]
                    at += 1
            out[at] = 101                                    # e
            out[at + 1] = 43 if e >= 0 else 45               # + or -
            at += 2
            x = abs(e)
            if x >= 100:
                out[at] = 48 + x // 100
                at += 1
            out[at] = 48 + (x // 10) % 10
            out[at + 1] = 48 + x % 10
            at += 2
        lengths[i] = at


@compiled
def join_rows(text, lengths, columns, labels, label_text, label_offsets):
    """The CSV body: rows of ``columns`` numbers, then their label, each line ending CR LF.

    ``text`` and ``lengths`` as :func:`format_g10` fills them, row-major;
    ``labels`` (rows,) int index into the label texts, stored one after the
    other in ``label_text`` uint8 from ``label_offsets`` (L + 1,).
    """
    rows = labels.shape[0]
    size = 0
    for i in range(lengths.shape[0]):
        size += lengths[i] + 1
    for r in range(rows):
        size += label_offsets[labels[r] + 1] - label_offsets[labels[r]] + 2
    body = np.empty(size, dtype=np.uint8)
    at = 0
    for r in range(rows):
        for c in range(columns):
            i = r * columns + c
            for j in range(lengths[i]):
                body[at] = text[i, j]
                at += 1
            body[at] = 44                                     # ,
            at += 1
        for j in range(label_offsets[labels[r]], label_offsets[labels[r] + 1]):
            body[at] = label_text[j]
            at += 1
        body[at], body[at + 1] = 13, 10
        at += 2
    return body
