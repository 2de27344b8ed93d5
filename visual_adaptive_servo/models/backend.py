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

"""Which implementation of the kinematic tensors runs: ``compiled`` (numba) or ``numpy``.

``compiled`` runs the kernels of :mod:`.kernels`; ``numpy`` the readable
reference the kernels are tested against.  The default (``backend=None``) is
``compiled`` when numba imports, else ``numpy``; the choice is logged once per
process (INFO; a WARNING when numba is missing).

Compiling the kernels takes about half a minute on the first start after an install
or an update of the package (numba caches them on disk for the next).
:func:`compile_notice` says so in the log, under :data:`NOTICE_LOGGER`, when a
compile outlasts :data:`NOTICE_AFTER`, so a first start does not look hung.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time

log = logging.getLogger(__name__)

#: the logger of the compile notices (``vas`` shows it at INFO whatever its ``-v``)
NOTICE_LOGGER = "visual_adaptive_servo.compile"
#: s a compile lasts before it is announced
NOTICE_AFTER = 2.0

BACKENDS = ("compiled", "numpy")

_kernels = None
_import_error = None
_logged = set()


def kernels():
    """The :mod:`.kernels` module, or None when numba cannot be imported (then see why_not)."""
    global _kernels, _import_error
    if _kernels is None and _import_error is None:
        try:
            with compile_notice("kinematic tensors"):
                from . import kernels as module
        except ImportError as exc:
            _import_error = exc
        else:
            _kernels = module
    return _kernels


def why_not():
    """Why the compiled backend is unavailable ('' when it is available)."""
    return "" if kernels() is not None else f"numba is not importable ({_import_error})"


def resolve_backend(backend, section="controller_node"):
    """The backend to run, ``"compiled"`` or ``"numpy"``, for the requested ``backend``.

    ``None`` chooses ``compiled`` when numba imports, else ``numpy``; asking
    for ``compiled`` without numba, or for an unknown name, is a ValueError
    naming ``<section>.backend``.
    """
    if backend is not None and backend not in BACKENDS:
        raise ValueError(f"{section}.backend: one of {list(BACKENDS)}, got {backend!r}")
    available = kernels() is not None
    if backend == "compiled" and not available:
        raise ValueError(f"{section}.backend: compiled needs numba, but {why_not()}; install "
                         f"it (python3 -m pip install numba) or choose numpy")
    chosen = backend or ("compiled" if available else "numpy")
    if chosen not in _logged:
        _logged.add(chosen)
        if chosen == "compiled":
            import numba

            log.info("kinematic tensors: compiled backend (numba %s, cache %s)",
                     numba.__version__, _kernels.cache_dir())
        elif backend is None:
            log.warning("kinematic tensors: numpy backend, %s", why_not())
        else:
            log.info("kinematic tensors: numpy backend (asked for)")
    return chosen


_notice_depth = 0
_explained = False      # the first notice of the process says why; the others only what


@contextlib.contextmanager
def compile_notice(what, after=None):
    """Log that ``what`` is being compiled, if the block outlasts ``after`` s (NOTICE_AFTER).

    A timer thread logs the notice while the block still runs (a first start spends
    half a minute here and would otherwise look hung); when the block ends after a
    notice, a second line says how long it took.  A block within another one is
    covered by the outer one's notice.  Blocks that load the kernels from numba's
    cache end well within ``after`` and log nothing.
    """
    global _notice_depth
    _notice_depth += 1
    if _notice_depth > 1:
        try:
            yield
        finally:
            _notice_depth -= 1
        return
    notices = logging.getLogger(NOTICE_LOGGER)
    announced = threading.Event()

    def announce():
        global _explained
        announced.set()
        if _explained:
            notices.info("compiling the %s with numba", what)
            return
        _explained = True
        notices.info("compiling the %s with numba: the first start after an install or an "
                     "update of the package takes up to a minute; the kernels are cached "
                     "for the next", what)

    timer = threading.Timer(NOTICE_AFTER if after is None else after, announce)
    timer.daemon = True
    start = time.perf_counter()
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        _notice_depth -= 1
        if announced.is_set():
            notices.info("%s compiled in %.0f s", what, time.perf_counter() - start)
