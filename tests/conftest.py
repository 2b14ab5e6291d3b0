"""Suite-wide pytest settings for running under pytest-xdist (``-n 2``, see ``[tool.pytest.ini_options]``).

Warp's kernel cache needs nothing here: the workers share it (``WARP_CACHE_PATH`` or Warp's default). Warp builds each
module in a folder of its own (``<module>_p<pid>_t<thread>``) and moves it into the cache with one ``os.rename``; a
process that loses that race moves its files in one by one with ``os.replace`` where they are missing, and a module
counts as cached only once both its binary and its ``.meta`` are there (``warp/_src/context.py``, ``Module._compile``;
the LTO cache does the same, ``warp/_src/build.py``). So a reader never sees a half-written file, and two workers that
compile the same module at once only cost the work twice. A per-worker cache would make that the rule, not the
exception. To keep the largest such double build off the critical path, the files whose first test builds the magnet
wrench module for the CPU (about 30 s cold) run on one worker (:func:`pytest_xdist_make_scheduler`).
"""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    """An xdist worker's base temp is ``<run's base temp>/popen-gwN``; make it ``<run's base temp>/gwN``.

    Ray puts Unix sockets at ``TEMP/session_<date>_<time>_<pid>/sockets/plasma_store``, which must stay under
    AF_UNIX's 107 bytes, so ``test_dataset_ray`` asks for a base temp of at most 40 characters
    (``/tmp/pytest-of-root/pytest-NNN/r0`` is 33): the six characters of ``popen-`` are what push a worker's over.
    Still inside the run's own base temp, so pytest's clean-up of old runs covers it. Runs before the tmpdir plugin's
    own ``pytest_configure``, which reads the option."""
    worker = getattr(config, "workerinput", None)
    basetemp = config.option.basetemp
    if worker is None or not basetemp:
        return
    p = Path(basetemp)
    if p.name == f"popen-{worker['workerid']}":
        config.option.basetemp = str(p.with_name(worker["workerid"]))


SAME_WORKER = {f"tests/{name}": "tests/<magnet wrench CPU build>"
               for name in ("test_calibration.py", "test_magnets_fields.py", "test_magnets_wrench.py")}
"""Test files that ``--dist loadfile`` hands to one worker as one unit, as if they were one file: each of these builds
``warpworm.kernels.magnet_wrench`` for the CPU when the kernel cache is cold, and two workers scheduled them at the
same moment (seen: both compiled it, 35 s each, on the 2-core machine with other jobs running). Only the schedule
changes: test ids, fixtures and order within a file are as before."""


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` with :data:`SAME_WORKER`'s files as one unit; any other ``--dist``: xdist's own."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class Scheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            return SAME_WORKER.get(scope, scope)

    return Scheduling(config, log)
