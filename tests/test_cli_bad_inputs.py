"""No traceback reaches a user: every command over a table of bad inputs (issue 25).

Each row runs ``warpworm CMD ARGS`` (in this process, through :func:`warpworm.cli.main`, in an empty working folder
holding a few prepared files) and asserts: exit code 2, exactly one line on stderr, no ``Traceback``, the line names
what was wrong (a fragment given in the row), and nothing was written (the folder's listing is unchanged). Every
command of the CLI, including ones added later, is also run with an unknown option. A few rows go through the real
console entry point (a subprocess) to check the same from outside.

Devices: ``cuda:99`` exists on no machine, so the "unavailable device" rows hold on a GPU machine too.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from warpworm.cli import COMMANDS, main

# (command line, fragment the one stderr line must contain)
BAD = [
    # generate: the config's own validation, the output folder, the arguments
    ("generate nosuch --out o", "packaged name"),
    ("generate bad.yaml --out o", "not valid YAML (line 3, column 4)"),
    ("generate unknown_key.yaml --out o", "sim.worldz: unknown key"),
    ("generate default --out o sim.dt=-1", "sim.dt: got -1"),
    ("generate default --out o sim.dt=.inf", "sim.dt: got inf; expected a finite number"),
    ("generate default --out o sim.dt=.nan", "sim.dt: got nan; expected a finite number"),
    ("generate default --out o sim.substeps=0", "sim.substeps: got 0; expected >= 1"),
    ("generate default --out o sim.substeps=1.5", "sim.substeps: got 1.5; expected an integer"),
    ("generate default --out o sim.device=cuda:99", "sim.device"),
    ("generate default --out o --num 0", "num_samples"),
    ("generate default --out o --workers 0", "--workers"),
    ("generate default --out junk", "no warpworm dataset"),
    ("generate default --out junk --resume", "no warpworm dataset"),
    ("generate default --out notes.txt", "it is a file"),
    ("generate default", "--out"),
    # simulate: the same rules as generate's for the same values
    ("simulate --cycles -1", "--cycles"),
    ("simulate --dt -0.01", "--dt (sim.dt): got -0.01; expected > 0"),
    ("simulate --dt inf", "--dt (sim.dt): got inf; expected a finite number"),  # was an internal error
    ("simulate --dt nan", "--dt (sim.dt): got nan; expected > 0"),
    ("simulate --substeps 0", "--substeps (sim.substeps): got 0; expected >= 1"),
    ("simulate --substeps 1.5", "--substeps: invalid int value: '1.5'"),
    ("simulate --worlds 0", "--worlds"),
    ("simulate --settle -1", "--settle"),
    ("simulate --device cuda:99", "--device"),
    ("simulate --set mu_static=-1", "worm.mu_static: got -1.0"),
    ("simulate --set hinge_stiffness=0", "worm.hinge_stiffness"),
    ("simulate --set no_such_field=1", "--set"),
    ("simulate --set mu_static=abc", "expected a number"),
    ("simulate --randomize nosuch", "packaged name"),
    ("simulate --fps 0", "--fps"),
    ("simulate --cycles x", "--cycles"),
    # render / demo / field
    ("render --device cuda:99", "--device"),
    ("render --worlds 0", "--worlds"),
    ("render --size 4", "--size"),
    ("render --cameras 0", "--cameras"),
    ("render --config nosuch", "packaged name"),
    ("render --out notes.txt", "it is a file"),
    ("demo --device cuda:99", "--device"),
    ("demo --height -0.01", "--height"),
    ("field --densities 0", "--densities"),
    # search-gait / experiment
    ("search-gait --cycles 0", "--cycles"),
    ("search-gait --grid w=abc", "--grid"),
    ("search-gait --grid q=1", "--grid"),
    ("search-gait --set mu_static=-1", "worm.mu_static"),
    ("search-gait --max-ratio 2", "--max-ratio"),
    ("search-gait --material nosuch", "nosuch"),
    ("experiment nosuch", "nosuch"),
    ("experiment compression --set mu_static=-1", "worm.mu_static"),
    ("experiment slope --worlds 0", "--worlds"),
    ("experiment strain --duration -1", "--duration"),
    ("experiment compression --fit nofile.csv", "nofile.csv"),
    ("experiment compression --material nosuch", "nosuch"),
    ("experiment compression --k-range 1 0.1", "--k-range"),
    # calibrate: missing, empty, non-finite, zero gap, a folder, bad sizes
    ("calibrate nofile.csv", "nofile.csv"),
    ("calibrate header.csv", "0 row(s)"),
    ("calibrate nan.csv", "got nan"),
    ("calibrate zero.csv", "gap_m"),
    ("calibrate junk", "not a file"),
    ("calibrate ok.csv --size 1 2", "--size"),
    ("calibrate ok.csv --shape cylinder", "--diameter"),
    # dataset readers and exports: no such folder, a file, a foreign folder, a non-empty OUT, bad numbers
    ("verify /no/such/dir", "no such folder"),
    ("verify notes.txt", "it is a file"),
    ("verify junk", "no manifest.json"),
    ("report /no/such/dir", "/no/such/dir"),
    ("report junk", "junk"),
    ("export-bop /no/such/dir out", "no such folder"),
    ("export-bop junk out", "no manifest.json"),
    ("export-coco notes.txt out", "it is a file"),
    ("export-yolo junk out", "no manifest.json"),
    ("export-webdataset /no/such/dir out", "no such folder"),
    ("export-usd nofile.npz --out t.usda", "nofile.npz"),
    ("export-usd notes.txt --out t.usda", "not a trajectory file"),
    ("export-usd ok.csv --out t.txt", "--out"),
    ("export-usd junk --out t.usda --worlds x", "--worlds"),
    ("config-schema --out /proc/nope/schema.json", "--out"),
    # the video commands (issue 26)
    ("track nofile.mp4 --camera nofile.json", "--camera"),
    ("fit-track nofile.csv --gait omega", "nofile.csv"),
]


@pytest.fixture()
def folder(tmp_path, monkeypatch):
    """An empty working folder with the inputs the rows name: a foreign folder, a text file, calibration tables."""
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "notes.txt").write_text("not a dataset\n")
    (tmp_path / "notes.txt").write_text("hello\n")
    (tmp_path / "header.csv").write_text("gap_m,force_N\n")
    (tmp_path / "nan.csv").write_text("gap_m,force_N\n0.001,1.0\n0.002,nan\n")
    (tmp_path / "zero.csv").write_text("gap_m,force_N\n0.0,1.0\n0.002,0.5\n")
    (tmp_path / "ok.csv").write_text("gap_m,force_N\n0.002,1.0\n0.004,0.5\n0.008,0.1\n")
    (tmp_path / "bad.yaml").write_text("name: x\nsim: [1,\n  ]: 2\n")
    (tmp_path / "unknown_key.yaml").write_text("name: x\nsim:\n  worldz: 3\n")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _listing(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def _run(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:  # argparse
        return exc.code


@pytest.mark.parametrize("line,fragment", BAD, ids=[b[0] for b in BAD])
def test_bad_input_is_one_line_exit_2_nothing_written(folder, capfd, line, fragment):
    if line.split()[0] not in COMMANDS:
        pytest.skip(f"no {line.split()[0]} command in this tree")
    before = _listing(folder)
    code = _run(line.split())
    out, err = capfd.readouterr()
    assert code == 2, (line, out, err)
    assert "Traceback" not in err + out
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1 and lines[0], (line, err)
    assert fragment in lines[0], (line, err)
    assert _listing(folder) == before, line  # nothing written, not even an empty folder


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_refuses_an_unknown_option_in_one_line(folder, capfd, name):
    code = _run([name, "--no-such-option"])
    _, err = capfd.readouterr()
    assert code == 2 and len(err.strip().split("\n")) == 1 and "error:" in err and "Traceback" not in err, err


def test_the_console_script_too(tmp_path):
    """Through the installed entry point: the same one line, exit 2, nothing in the folder."""
    for argv in (["simulate", "--device", "cuda:99"], ["calibrate", "nofile.csv"], ["verify", "/no/such/dir"]):
        r = subprocess.run([sys.executable, "-m", "warpworm", *argv], capture_output=True, text=True, timeout=120,
                           cwd=tmp_path, env={**os.environ, "WARPWORM_DEBUG": ""})
        assert r.returncode == 2 and len(r.stderr.strip().split("\n")) == 1 and "Traceback" not in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []


def test_an_internal_error_is_one_line_too(folder, capfd, monkeypatch):
    """A bug (an exception no command expected) is one line and exit 1; WARPWORM_DEBUG=1 shows the traceback."""
    import warpworm.commands.verify as verify

    def boom(*a, **k):
        raise KeyError("something broke")

    monkeypatch.setattr(verify, "verify_dataset", boom)
    monkeypatch.setattr(verify, "dataset_folder", lambda *a, **k: None)
    monkeypatch.delenv("WARPWORM_DEBUG", raising=False)
    assert _run(["verify", "junk"]) == 1
    err = capfd.readouterr().err
    assert len(err.strip().split("\n")) == 1 and "internal error" in err and "WARPWORM_DEBUG=1" in err
    monkeypatch.setenv("WARPWORM_DEBUG", "1")
    with pytest.raises(KeyError):
        main(["verify", "junk"])


@pytest.mark.parametrize("dt,substeps,must", [
    (0.0, 2, ["Simulator dt: got 0.0; expected a finite step > 0 [s]"]),
    (-4e-3, 2, ["Simulator dt: got -0.004; expected a finite step > 0 [s]"]),
    (4e-3, 0, ["Simulator substeps: got 0; expected a whole number >= 1"]),
    (0, -1, ["Simulator dt: got 0; expected", "Simulator substeps: got -1; expected"]),
    (float("inf"), 2, ["Simulator dt: got inf; expected a finite step > 0 [s]"]),
    (float("nan"), 2, ["Simulator dt: got nan; expected"]),
    (4e-3, 1.5, ["Simulator substeps: got 1.5; expected a whole number >= 1"]),
    (4e-3, float("nan"), ["Simulator substeps: got nan; expected a whole number >= 1"]),
])
def test_simulator_refuses_bad_dt_and_substeps_by_name(dt, substeps, must, monkeypatch):
    """The library's own refusal (for callers that skip the CLI's checks): key, value and expectation, one line,
    raised before the solver is built (no work: SubstepSettings is never reached)."""
    from warpworm.physics.params import WormParams
    from warpworm.sim import simulator
    from warpworm.sim.model import Model

    model = Model.from_params(WormParams(), 1)
    monkeypatch.setattr(simulator, "SubstepSettings", lambda *a, **k: pytest.fail("work started"))
    with pytest.raises(ValueError) as info:
        simulator.Simulator(model, dt=dt, substeps=substeps)
    msg = str(info.value)
    assert "\n" not in msg and all(m in msg for m in must), msg
