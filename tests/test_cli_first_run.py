"""The first run says it is compiling kernels, and the summary counts it (issue 25: a cold cache sat at 0 % for ~24 s
and the stage times did not account for it). A stand-in stage plays the cold cache: its kernel warm-up returns only
once the notice has been logged (an event, not a sleep), with the notice threshold lowered to 0.05 s, so no real
compile is needed and no timing decides the outcome; a warm cache is a warm-up that returns at once."""

from __future__ import annotations

import re
import threading

from test_dataset_fakes import FakeStages

from warpworm.data import job
from warpworm.data.config import load_config

NOTICED = threading.Event()
"""Set by the test's log when the 'compiling' notice is logged; the cold warm-up waits on it."""
WARM_CALLS = []
"""The configs the stand-ins' warm() was called with (the warm-cache test checks that the cache logic ran)."""


class SlowWarmStages(FakeStages):
    """FakeStages whose kernel warm-up lasts until the 'compiling' notice is out (what compiling is to a first run)."""

    def warm(self, cfg):
        WARM_CALLS.append(cfg)
        assert NOTICED.wait(60), "the compiling notice never came"


class WarmCacheStages(FakeStages):
    """FakeStages whose kernel warm-up returns at once (the kernels load from the cache)."""

    def warm(self, cfg):
        WARM_CALLS.append(cfg)


def _tiny():
    return load_config({"num_samples": 4, "shard_size": 4, "sim": {"worlds": 1, "frame_times": [0.1, 0.2, 0.3, 0.4]},
                        "render": {"width": 16, "height": 12}, "output": {"preview": False}})


def _log(lines):
    def log(line):
        lines.append(line)
        if "compiling Warp kernels" in line:
            NOTICED.set()
    return log


def test_generate_says_it_compiles_and_counts_it(tmp_path, monkeypatch):
    monkeypatch.setattr(job, "KERNEL_NOTICE_S", 0.05)
    NOTICED.clear()
    WARM_CALLS.clear()
    lines = []
    s = job.generate(_tiny(), tmp_path / "d", stages="test_cli_first_run:SlowWarmStages", progress=False,
                     log=_log(lines))
    assert WARM_CALLS  # (the in-process worker warms once more: a cached no-op)
    said = [ln for ln in lines if "compiling Warp kernels" in ln]
    assert len(said) == 1 and "cached for later runs" in said[0]
    assert any(ln.startswith("kernels ready in") for ln in lines)
    # the warm-up outlasted the notice threshold: a lower bound, whatever the machine's speed
    assert s.kernels_s >= job.KERNEL_NOTICE_S and s.wall_s >= s.kernels_s
    m = re.search(r"kernels (\d+\.\d) s \(compiled: first run\)", s.text())
    assert m and abs(float(m.group(1)) - s.kernels_s) <= 0.05, s.text()


def test_a_warm_cache_says_nothing(tmp_path):
    """The warm-up runs (the cache logic is exercised) and, being fast, says nothing and marks nothing compiled."""
    NOTICED.clear()
    WARM_CALLS.clear()
    lines = []
    s = job.generate(_tiny(), tmp_path / "d", stages="test_cli_first_run:WarmCacheStages", progress=False,
                     log=_log(lines))
    assert WARM_CALLS  # warm() was called: the notice logic ran
    assert s.kernels_s < job.KERNEL_NOTICE_S
    assert not any("compiling" in ln or "kernels ready" in ln for ln in lines) and "compiled" not in s.text()
    assert re.search(r"kernels \d+\.\d s", s.text()), s.text()


def test_commands_notice_a_cold_kernel_cache(tmp_path, monkeypatch, capfd):
    import warp as wp

    from warpworm.commands.common import first_run_notice

    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    assert first_run_notice() is True
    assert "compiling Warp kernels" in capfd.readouterr().err
    for m in ("warpworm.kernels.implicit_euler", "warpworm.kernels.magnet_wrench"):
        (tmp_path / f"wp_{m}_0123abc").mkdir()
    assert first_run_notice() is False and capfd.readouterr().err == ""


def test_a_command_imports_its_own_module_only():
    # start-up: `warpworm CMD` loads CMD's module, not every command's (their imports cost the job ~0.5 s); a fresh
    # interpreter, so modules other tests imported do not count
    import subprocess
    import sys

    code = ("import sys; from warpworm.cli import main; main(['config-schema']); "
            "print('LOADED', sorted(m for m in sys.modules if m.startswith('warpworm.commands.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    loaded = out.rsplit("LOADED", 1)[1]
    assert "warpworm.commands.config_schema" in loaded
    assert "warpworm.commands.simulate" not in loaded and "warpworm.commands.generate" not in loaded, loaded
    # and --help lists every command with its help line, importing none (the lines are read from the sources)
    code = ("import sys\nfrom warpworm.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print('LOADED', sorted(m for m in sys.modules if m.startswith('warpworm.commands.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    listing, loaded = out.rsplit("LOADED", 1)
    assert loaded.strip() == "[]", loaded
    assert "Generate a labeled synthetic dataset" in " ".join(listing.split())
