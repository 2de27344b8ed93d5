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

"""Feature detector: time per 640x480 frame (OpenCV vs numpy) and centroid accuracy.

Timing: :func:`detection.detect` on a 640x480 frame with 3 markers (radius
6 px) against the same pipeline written in numpy alone (:func:`numpy_detect`:
the same threshold, crop, 8-connected components by label propagation, area
test and unmixed centroid, with numpy for every OpenCV call), plus the parts of
each.  Every call is timed on its own with ``time.perf_counter_ns`` after a
warm-up; medians and p99 are reported.  A frame of uniform colour noise (every
marker colour scattered over the whole frame: components over the full mask)
shows the worst case of the OpenCV pipeline.

Accuracy: the largest and RMS centroid error over random sub-pixel positions
of anti-aliased discs (the tests' renderer, test/conftest.draw_discs, whose
true centroids are exact), for the unmixed centroid of ``detect`` and for the
thresholded blob's own centroid, noiseless, blurred (Gaussian, sigma 1 px) and
with pixel noise (sigma 3 levels).

Usage::

    python benchmarks/bench_detection.py [--frames N] [--positions P]

Prints markdown tables and writes benchmarks/results/detection.json.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import cv2
import numpy as np
from benchlib import environment, write_result

from visual_adaptive_servo.vision.detection import (
    BACKGROUND_GAP,
    CROP_MARGIN,
    EDGE_MARGIN,
    DetectorConfig,
    detect,
)

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results", "detection.json")
sys.path.insert(0, os.path.join(HERE, os.pardir, "test"))
from conftest import draw_discs  # noqa: E402  the tests' oracle renderer

COLORS = ((230, 30, 30), (30, 200, 30), (40, 90, 255))
H, W = 480, 640


def _config():
    return DetectorConfig(np.ravel(COLORS), 40.0, (10.0, 5000.0), (0.0, 0.0), (1.0, 1.0))


def _frame(rng, radius=6.0):
    centres = np.array([[150.0, 120.0], [320.0, 300.0], [500.0, 180.0]]) + rng.random((3, 2))
    return draw_discs(H, W, [(c, r, radius, col) for (c, r), col in zip(centres, COLORS)])


# -- the numpy pipeline ------------------------------------------------------------
def numpy_mask(rgb, lower, upper):
    return np.all((rgb >= lower) & (rgb <= upper), axis=2)


def numpy_dilate(mask, radius):
    """Binary dilation by a (2 radius + 1)^2 square."""
    h, w = mask.shape
    padded = np.pad(mask, radius)
    out = np.zeros_like(mask)
    for dr in range(2 * radius + 1):
        for dc in range(2 * radius + 1):
            out |= padded[dr:dr + h, dc:dc + w]
    return out


def numpy_labels(mask):
    """8-connected components: every pixel takes the smallest flat index of its component."""
    h, w = mask.shape
    none = h * w
    labels = np.where(mask, np.arange(none).reshape(h, w), none)
    while True:
        padded = np.pad(labels, 1, constant_values=none)
        smallest = labels.copy()
        for dr in range(3):
            for dc in range(3):
                np.minimum(smallest, padded[dr:dr + h, dc:dc + w], out=smallest)
        smallest[~mask] = none
        if np.array_equal(smallest, labels):
            return labels
        labels = smallest


def numpy_detect(rgb, config):
    """(2m,) pixels or None: :func:`detect`'s pipeline with numpy instead of OpenCV."""
    h, w, _ = rgb.shape
    points = []
    for lower, upper in zip(config.lower, config.upper):
        mask = numpy_mask(rgb, lower, upper)
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        if rows.size == 0:
            return None
        r0, r1 = max(rows[0] - CROP_MARGIN, 0), min(rows[-1] + 1 + CROP_MARGIN, h)
        c0, c1 = max(cols[0] - CROP_MARGIN, 0), min(cols[-1] + 1 + CROP_MARGIN, w)
        labels = numpy_labels(mask[r0:r1, c0:c1])
        names, areas = np.unique(labels[labels < labels.size], return_counts=True)
        kept = names[(areas >= config.blob_area[0]) & (areas <= config.blob_area[1])]
        if kept.size != 1:
            return None
        blob = labels == kept[0]
        near = numpy_dilate(blob, EDGE_MARGIN) & ((labels == labels.size) | blob)
        far = ~numpy_dilate(blob, EDGE_MARGIN + BACKGROUND_GAP)
        roi = rgb[r0:r1, c0:c1].astype(np.float64)
        marker, background = np.median(roi[blob], axis=0), np.median(roi[far], axis=0)
        contrast = marker - background
        coverage = np.clip((roi - background) @ (contrast / (contrast @ contrast)), 0.0, 1.0)
        coverage[~near] = 0.0
        total = coverage.sum()
        points.append([coverage.sum(axis=0) @ (np.arange(c0, c1) + 0.5) / total,
                       coverage.sum(axis=1) @ (np.arange(r0, r1) + 0.5) / total])
    return ((np.array(points) - config.pixel_origin) * config.pixel_axes).reshape(-1)


# -- timing ----------------------------------------------------------------------
def _time(fn, repeats):
    fn()
    ns = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        ns.append(time.perf_counter_ns() - t0)
    us = np.array(ns) / 1e3
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "samples": int(us.size)}


def timing(frames, rng):
    config = _config()
    image, _ = _frame(rng)
    noise = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    lower, upper = config.lower[0], config.upper[0]
    mask = cv2.inRange(image, lower, upper)
    x, y, w, h = cv2.boundingRect(mask)
    crop = mask[y - CROP_MARGIN:y + h + CROP_MARGIN, x - CROP_MARGIN:x + w + CROP_MARGIN]
    noise_mask = cv2.inRange(noise, lower, upper)
    numpy_pixels = numpy_detect(image, config)
    assert np.allclose(numpy_pixels, detect(image, config).pixels, atol=1e-9)
    few = max(frames // 10, 20)      # the slow numpy parts
    return {
        "detect (OpenCV), 3 markers": _time(lambda: detect(image, config), frames),
        "numpy_detect, 3 markers": _time(lambda: numpy_detect(image, config), few),
        "detect (OpenCV), colour noise frame": _time(lambda: detect(noise, config), few),
        "threshold: cv2.inRange": _time(lambda: cv2.inRange(image, lower, upper), frames),
        "threshold: numpy": _time(lambda: numpy_mask(image, lower, upper), few),
        "bounding box: cv2.boundingRect": _time(lambda: cv2.boundingRect(mask), frames),
        "bounding box: numpy any": _time(
            lambda: (np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))),
            frames),
        "components on the marker crop: cv2": _time(
            lambda: cv2.connectedComponentsWithStats(crop, connectivity=8), frames),
        "components on the marker crop: numpy": _time(lambda: numpy_labels(crop > 0), frames),
        "components on the whole 640x480 mask: cv2": _time(
            lambda: cv2.connectedComponentsWithStats(mask, connectivity=8), few),
        "components on a colour noise mask: cv2": _time(
            lambda: cv2.connectedComponentsWithStats(noise_mask, connectivity=8), few),
    }


# -- accuracy --------------------------------------------------------------------
def _blob_centroid(image, color, tolerance):
    lower = np.clip(np.ceil(np.subtract(color, tolerance)), 0, 255).astype(np.uint8)
    upper = np.clip(np.floor(np.add(color, tolerance)), 0, 255).astype(np.uint8)
    _, _, stats, centroids = cv2.connectedComponentsWithStats(cv2.inRange(image, lower, upper),
                                                              connectivity=8)
    return centroids[1 + np.argmax(stats[1:, cv2.CC_STAT_AREA])] + 0.5


def accuracy(positions, rng):
    config = DetectorConfig(COLORS[0], 40.0, (4.0, 5000.0), (0.0, 0.0), (1.0, 1.0))
    rows = []
    for blur, noise in ((0.0, 0.0), (1.0, 0.0), (0.0, 3.0)):
        for radius in (3.0, 4.0, 6.0, 10.0):
            unmixed, blob = [], []
            for _ in range(positions):
                image, truth = draw_discs(64, 64, [(32.0 + rng.random(), 32.0 + rng.random(),
                                                    radius, COLORS[0])])
                picture = image.astype(float)
                if blur:
                    picture = cv2.GaussianBlur(picture, (0, 0), blur)
                picture += noise * rng.standard_normal(picture.shape)
                image = np.clip(np.rint(picture), 0, 255).astype(np.uint8)
                unmixed.append(np.abs(detect(image, config).pixels - truth[0]))
                blob.append(np.abs(_blob_centroid(image, COLORS[0], 40.0) - truth[0]))
            unmixed, blob = np.array(unmixed), np.array(blob)
            rows.append({"blur_sigma_px": blur, "noise_sigma": noise, "radius_px": radius,
                         "unmixed_max_px": float(unmixed.max()),
                         "unmixed_rms_px": float(np.sqrt(np.mean(unmixed ** 2))),
                         "blob_max_px": float(blob.max()),
                         "blob_rms_px": float(np.sqrt(np.mean(blob ** 2)))})
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=500, help="timed calls per case")
    parser.add_argument("--positions", type=int, default=200,
                        help="random sub-pixel positions per accuracy case")
    parser.add_argument("--out", default=RESULTS, help="JSON result file")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(20150101)

    times = timing(args.frames, rng)
    print(f"time per call, 640x480 frame (OpenCV {cv2.__version__}, numpy {np.__version__})\n")
    print("| call | median [µs] | p99 [µs] |")
    print("|---|---:|---:|")
    for name, s in times.items():
        print(f"| {name} | {s['median_us']:.1f} | {s['p99_us']:.1f} |")

    rows = accuracy(args.positions, rng)
    print(f"\ncentroid error per coordinate, {args.positions} sub-pixel positions [px]\n")
    print("| blur sigma | noise sigma | radius | unmixed max | unmixed RMS | blob max "
          "| blob RMS |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['blur_sigma_px']:g} | {r['noise_sigma']:g} | {r['radius_px']:g} | "
              f"{r['unmixed_max_px']:.4f} | {r['unmixed_rms_px']:.4f} | {r['blob_max_px']:.4f} | "
              f"{r['blob_rms_px']:.4f} |")
    write_result(args.out, {"timing": times, "accuracy": rows, "opencv": cv2.__version__,
                            "opencv_threads": cv2.getNumThreads(), **environment()})


if __name__ == "__main__":
    main()
