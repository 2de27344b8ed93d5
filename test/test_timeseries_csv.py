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

"""timeseries.csv: the compiled number formatting against Python's, the file against csv's.

Oracles: Python's own ``"%.10g" % v`` for every number, and ``csv.writer``
writing ``[f"{v:.10g}" for v in row] + [label]`` row by row (what the runner
wrote before) for the whole file, with and without numba.
"""

import csv

import numpy as np
import pytest

from visual_adaptive_servo.recording import recorder

NEEDS_NUMBA = "the compiled formatting needs numba"


def awkward_numbers(rng, size):
    """Doubles of every kind: run-like values, all magnitudes, any bits, near rounding ties."""
    ties = (rng.integers(10**9, 10**10, size) + 0.5) * 10.0 ** rng.integers(-15, 15, size)
    return np.concatenate([
        rng.normal(size=size) * 10.0 ** rng.integers(-12, 13, size),
        rng.uniform(-1.0, 1.0, size) * 10.0 ** rng.uniform(-300.0, 300.0, size),
        np.frombuffer(rng.bytes(8 * size), dtype=np.float64),
        ties, np.nextafter(ties, 0.0), np.nextafter(ties, np.inf),
        10.0 ** np.arange(-320, 309), np.nextafter(10.0 ** np.arange(-300, 300), 0.0),
        [0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, 2.2250738585072014e-308,
         1.7976931348623157e308, 9999999999.5, 999999999.95, 0.0001, 0.00001, 1e10, 1e9,
         123456789012.0, 0.00012345678905, 65.0, -0.5, 1.0807],
    ])


def test_compiled_numbers_are_pythons_g10_exactly(rng):
    pytest.importorskip("numba", reason=NEEDS_NUMBA)
    from visual_adaptive_servo.recording import csv_kernels

    values = awkward_numbers(rng, 100_000)
    text = np.empty((len(values), csv_kernels.WIDTH), dtype=np.uint8)
    lengths = np.empty(len(values), dtype=np.intp)
    undecided = np.empty(len(values), dtype=np.bool_)
    csv_kernels.format_g10(values, text, lengths, undecided)
    # what is left to Python: near-ties and extreme magnitudes only, not run-like values
    assert undecided[:100_000].mean() < 1e-3
    decided = np.flatnonzero(~undecided)
    assert len(decided) > 0.4 * len(values)
    wrong = [(values[i], text[i, :lengths[i]].tobytes().decode()) for i in decided
             if text[i, :lengths[i]].tobytes().decode() != "%.10g" % values[i]]
    assert not wrong, wrong[:5]


def csv_module_file(path, columns, table, labels):
    """timeseries.csv as the runner wrote it before: csv.writer, one row at a time."""
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for row, label in zip(table, labels):
            writer.writerow([f"{float(v):.10g}" for v in row] + [label])


@pytest.mark.parametrize("compiled", [True, False], ids=["numba", "python"])
def test_timeseries_csv_is_byte_for_byte_what_csv_writer_writes(
        tmp_path, rng, compiled, monkeypatch):
    values = awkward_numbers(rng, 2000)
    columns = 7
    table = values[:len(values) // columns * columns].reshape(-1, columns)
    statuses = ["ok", "hold", "fallback", "", 'odd, "quoted"', "line\nbreak"]
    labels = [statuses[k] for k in rng.integers(0, len(statuses), len(table))]
    names = [f"c.{k}" for k in range(columns)] + ["status"]
    if compiled:
        pytest.importorskip("numba", reason=NEEDS_NUMBA)
    else:
        monkeypatch.setattr(recorder, "_csv_kernels", lambda: None)
    monkeypatch.setattr(recorder, "CSV_BLOCK_ROWS", 333)   # several blocks
    recorder.write_csv(tmp_path / "fast.csv", names, table, labels)
    csv_module_file(tmp_path / "reference.csv", names, table, labels)
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "reference.csv").read_bytes()


def test_an_empty_run_writes_the_header_only(tmp_path):
    recorder.write_csv(tmp_path / "empty.csv", ["t", "status"], np.zeros((0, 1)), [])
    assert (tmp_path / "empty.csv").read_bytes() == b"t,status\r\n"


def test_table_and_labels_of_different_lengths_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"write_csv: table \(N, C\) and N labels"):
        recorder.write_csv(tmp_path / "bad.csv", ["t", "status"], np.zeros((3, 1)), ["ok"])
