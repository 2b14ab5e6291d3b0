"""The ``warpworm`` program's garbage collection (``cli.run``): none while it starts (imports and kernel definitions
make long-lived objects: full collections of them cost ~0.13 CPU-s per process), on while the command runs (a long
job must free its cycles), the start-up's objects frozen."""

import json
import subprocess
import sys
import textwrap

PROBE = textwrap.dedent("""
    import gc, json, sys
    full = []  # generation-2 collections started
    gc.callbacks.append(lambda phase, info: phase == "start" and info["generation"] == 2 and full.append(1))
    from warpworm import cli
    seen = {}
    start_up_done = cli._collect_from_here
    def spy():
        seen["full_in_start_up"] = len(full)
        start_up_done()
        seen["enabled_for_command"] = gc.isenabled()
        seen["frozen"] = gc.get_freeze_count()
    cli._collect_from_here = spy
    sys.argv = ["warpworm"] + sys.argv[1:]
    try:
        cli.run()
    except SystemExit as e:
        seen["status"] = e.code
    print(json.dumps(seen))
""")


def test_the_program_starts_without_full_collections_and_collects_while_the_command_runs(tmp_path):
    out = subprocess.run([sys.executable, "-c", PROBE, "generate", "default", "--num", "1", "sim.worlds=1",
                          "output.preview=false", "--workers", "1", "--out", str(tmp_path / "ds")],
                         capture_output=True, text=True, timeout=600)
    seen = json.loads(out.stdout.strip().splitlines()[-1])  # the probe's last line
    assert seen["status"] == 0, out.stderr[-2000:]
    assert seen["full_in_start_up"] == 0  # the code before: 2 (warp's import, the generate command's)
    assert seen["enabled_for_command"] is True
    assert seen["frozen"] > 100_000  # Warp's builtins and the kernels' definitions
