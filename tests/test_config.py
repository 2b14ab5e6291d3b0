"""Config loading: every mistake stops before any work with a message naming the key path, the value and what was
expected; overrides; packaged configs."""

import dataclasses
import math
import subprocess
import sys

import pytest

from warpworm.data.dataset import check_output_dir
from warpworm.data.config import (PARAM_SPECS, ConfigError, OutputConfig, RenderConfig, SimConfig,
                             config_packaged_names, load_config)
from warpworm.physics.params import WormParams
from warpworm.data.randomize import Constant, Uniform

GOOD = {"num_samples": 8, "shard_size": 4, "sim": {"frame_times": [0.1, 0.2]}}


def _err(raw, overrides=()):
    with pytest.raises(ConfigError) as e:
        load_config(raw, list(overrides))
    return str(e.value)


@pytest.mark.parametrize("raw, must", [
    ({"bogus": 1}, ["bogus", "unknown key", "num_samples"]),
    ({"sim": {"substepz": 3}}, ["sim.substepz", "unknown key", "substeps"]),
    ({"sim": {"substeps": "many"}}, ["sim.substeps", "'many'", "integer"]),
    ({"sim": {"dt": "0.1"}}, ["sim.dt", "'0.1'", "number"]),
    ({"render": {"camera_per_frame": "yes"}}, ["render.camera_per_frame", "'yes'", "true or false"]),
    ({"num_samples": -5}, ["num_samples", "-5", ">= 1"]),
    ({"shard_size": 0}, ["shard_size", "0", ">= 1"]),
    ({"sim": {"worlds": -1}}, ["sim.worlds", "-1", ">= 1"]),
    ({"sim": {"dt": 0}}, ["sim.dt", "0", "> 0"]),
    ({"render": {"width": -64}}, ["render.width", "-64", ">= 8"]),
    ({"randomize": {"worm": {"mu_static": {"uniform": [0.3, 0.2]}}}}, ["randomize.worm.mu_static", "0.3", "low <= high"]),
    ({"randomize": {"camera": {"distance": {"loguniform": [0.5, 0.1]}}}}, ["randomize.camera.distance", "low <= high"]),
    ({"randomize": {"worm": {"gait": "crawl"}}}, ["randomize.worm.gait", "'crawl'", "peristaltic"]),
    ({"randomize": {"worm": {"gait": {"choice": ["omega", "slither"]}}}}, ["randomize.worm.gait", "'slither'", "omega"]),
    ({"randomize": {"worm": {"magnet_model": "magic"}}}, ["randomize.worm.magnet_model", "'magic'", "analytic"]),
    ({"randomize": {"worm": {"kalpha": 1.0}}}, ["randomize.worm.kalpha", "unknown parameter", "hinge_stiffness"]),
    ({"randomize": {"weather": {}}}, ["randomize.weather", "unknown group", "camera"]),
    ({"randomize": {"worm": {"a": -0.01}}}, ["randomize.worm.a", "-0.01", "> 0"]),
    ({"randomize": {"worm": {"a": {"gauss": [1, 2]}}}}, ["randomize.worm.a", "gauss", "uniform"]),
    ({"randomize": {"worm": {"a": {"normal": {"mean": 0.02}}}}}, ["randomize.worm.a", "normal", "std"]),
    ({"randomize": {"camera": {"fov_y": {"normal": {"mean": 0.7, "std": 0.1, "low": 0.9, "high": 0.5}}}}},
     ["randomize.camera.fov_y", "low <= high"]),
    # camera ranges are what warpworm.render.sample_cameras draws from: constants or uniforms; settings are constants
    ({"randomize": {"camera": {"distance": {"loguniform": [0.1, 0.5]}}}}, ["randomize.camera.distance", "uniform"]),
    ({"randomize": {"camera": {"roll": {"normal": {"mean": 0, "std": 0.1}}}}}, ["randomize.camera.roll", "uniform"]),
    ({"randomize": {"camera": {"min_in_frame": 1.5}}}, ["randomize.camera.min_in_frame", "1.5", "<= 1.0"]),
    ({"randomize": {"camera": {"min_in_frame": -0.1}}}, ["randomize.camera.min_in_frame", "-0.1", ">= 0.0"]),
    ({"randomize": {"camera": {"min_in_frame": {"uniform": [0.5, 0.9]}}}},
     ["randomize.camera.min_in_frame", "expected a constant"]),
    ({"randomize": {"camera": {"max_tries": 0}}}, ["randomize.camera.max_tries", ">= 1"]),
    ({"randomize": {"camera": {"max_tries": 2.5}}}, ["randomize.camera.max_tries", "2.5", "whole number"]),
    ({"randomize": {"camera": {"lookat_jitter": {"uniform": [0, 0.01]}}}},
     ["randomize.camera.lookat_jitter", "expected a constant"]),
    ({"sim": {"frame_times": [0.5, 0.2]}}, ["sim.frame_times", "increasing"]),
    ({"sim": {"frame_times": [0.1, 0.2, 0.3]}, "shard_size": 4}, ["shard_size", "4", "multiple"]),
    ({"output": {"compression": "zstd"}}, ["output.compression", "'zstd'", "lzf"]),
    ({"sim": {"device": "cuda:99"}}, ["sim.device", "'cuda:99'", "Warp device available here"]),
    ({"sim": {"dt": 0.004, "frame_times": [0.25, 0.501]}}, ["sim.frame_times", "0.501", "multiples of sim.dt"]),
    ({"sim": [1, 2]}, ["sim", "mapping"]),
    # each key alone, as pydantic reports it: the path (list items by index), the value, what was expected
    ({"sim": {"frame_times": [0.1, "x"]}}, ["sim.frame_times[1]", "'x'", "a number"]),
    ({"sim": {"frame_times": []}}, ["sim.frame_times", "[]", "non-empty list"]),
    ({"sim": {"frame_times": 0.1}}, ["sim.frame_times", "0.1", "list of numbers"]),
    ({"sim": {"dt": float("inf")}}, ["sim.dt", "inf", "finite number"]),
    ({"sim": {"worlds": True}}, ["sim.worlds", "True", "integer"]),
    ({"sim": {"worlds": 2.5}}, ["sim.worlds", "2.5", "integer"]),
    ({"name": 3}, ["name", "3", "string"]),
    ({"render": {"widht": 64}}, ["render.widht", "unknown key", "width"]),
    ({"sim": {3: 1}}, ["sim.3: unknown key", "substeps"]),  # YAML '3: 1': a key that is not a string
    ({"output": {"compression_level": 12}}, ["output.compression_level", "12", "<= 9"]),
    ({"output": "gzip"}, ["output", "'gzip'", "mapping with keys", "compression"]),
    ({"randomize": [1]}, ["randomize", "[1]", "mapping with keys", "worm"]),
    ({"randomize": {"worm": [1]}}, ["randomize.worm", "[1]", "mapping of parameters"]),
    ({"randomize": {"worm": {"backward": 1}}}, ["randomize.worm.backward", "1", "[False, True]"]),
    ({"randomize": {"worm": {"a": float("nan")}}}, ["randomize.worm.a", "nan", "a number"]),  # NaN: presets only
    ({"randomize": {"worm": {"gait": {"uniform": [0, 1]}}}}, ["randomize.worm.gait", "choice/grid"]),
    ({"randomize": {"texture": {"floor": "wood"}}}, ["randomize.texture.floor", "'wood'", "checker"]),
    ({"randomize": {"sensor": {"jpeg_quality": {"choice": [100, 0]}}}}, ["randomize.sensor.jpeg_quality", ">= 1"]),
])
def test_bad_config_names_path_value_and_expectation(raw, must):
    msg = _err({**GOOD, **raw})
    for m in must:
        assert m in msg, (m, msg)


def test_all_errors_reported_at_once():
    msg = _err({"bogus": 1, "sim": {"dt": -1}, "randomize": {"worm": {"gait": "crawl"}}})
    assert "bogus" in msg and "sim.dt" in msg and "randomize.worm.gait" in msg
    # one message per problem, in every section
    with pytest.raises(ConfigError) as e:
        load_config({"seed": -1, "sim": {"worlds": 0, "device": 3}, "render": {"width": "wide"},
                     "output": {"preview": "no"}, "randomize": {"light": {"ambient": 2}, "weather": {}}})
    paths = sorted(m.split(":")[0] for m in e.value.errors)
    assert paths == ["output.preview", "randomize.light.ambient", "randomize.weather", "render.width", "seed",
                     "sim.device", "sim.worlds"], e.value.errors


def test_a_check_relating_two_keys_names_the_key_to_change():
    # shard_size is checked against sim.frame_times (its own key named, not sim's), frame times against sim.dt
    with pytest.raises(ConfigError) as e:
        load_config({"shard_size": 6, "sim": {"frame_times": [0.2, 0.4, 0.6, 0.8]}})
    assert e.value.errors == ["shard_size: got 6; expected a multiple of len(sim.frame_times) = 4 (a shard holds "
                              "whole trajectories)"]


def test_defaults_and_coercions_match_the_documented_schema():
    cfg = load_config({"sim": None, "render": None, "randomize": {"worm": None}})  # an empty section = defaults
    assert cfg.sim == SimConfig() and cfg.render == RenderConfig() and cfg.output == OutputConfig()
    assert cfg.randomize["worm"]["a"] == Constant(WormParams().a)
    assert math.isnan(cfg.randomize["worm"]["orientation"].value)  # NaN: the gait preset's value
    # integers are numbers, stored as floats, so the YAML (and the files' config_yaml) reads the same however written
    cfg = load_config({"num_samples": 4, "shard_size": 2, "sim": {"dt": 1, "settle_time": 0, "frame_times": [1, 2]}})
    assert type(cfg.sim.dt) is float and cfg.sim.frame_times == [1.0, 2.0]
    assert all(type(t) is float for t in cfg.sim.frame_times) and "settle_time: 0.0" in cfg.to_yaml()
    # every parameter is there, in PARAM_SPECS' order, named or not
    assert {g: list(p) for g, p in cfg.randomize.items()} == {g: list(p) for g, p in PARAM_SPECS.items()}


def test_every_param_spec_default_is_a_valid_value_of_its_spec():
    for group, specs in PARAM_SPECS.items():
        for name, spec in specs.items():
            load_config({**GOOD, "randomize": {group: {name: spec.default}}})


def test_code_built_configs_are_not_validated():
    # the pipeline derives configs with dataclasses.replace (the preview's dense frame list is not on sim.dt's grid)
    cfg = load_config("default")
    dense = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, frame_times=[0.0, 0.05, 0.1]), shard_size=3)
    assert dense.frames_per_trajectory == 3 and dense.num_shards == -(-cfg.num_samples // 3)


def test_dotted_overrides_and_yaml_values():
    cfg = load_config(GOOD, ["sim.substeps=20", "randomize.worm.mu_static={uniform: [0.2, 0.3]}", "name=x"])
    assert cfg.sim.substeps == 20 and cfg.name == "x"
    assert cfg.randomize["worm"]["mu_static"] == Uniform(0.2, 0.3)
    assert "sim.substepz" in _err(GOOD, ["sim.substepz=3"])
    assert "expected key.path=value" in _err(GOOD, ["sim.substeps"])


def test_resolved_config_round_trips_through_yaml():
    import yaml

    cfg = load_config("default")
    again = load_config(yaml.safe_load(cfg.to_yaml()))
    assert again.to_dict() == cfg.to_dict() or yaml.safe_dump(again.to_dict()) == yaml.safe_dump(cfg.to_dict())


def test_packaged_configs_all_validate():
    names = config_packaged_names()
    assert "default" in names and len(names) >= 6
    for n in names:
        load_config(n)
    assert "expected a YAML file path or a packaged name" in _err("no_such_config")


def test_output_folder_checks(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("1")
    # a folder of someone else's files is refused, with or without --resume (issue 25: --resume wrote next to them)
    for resume in (False, True):
        with pytest.raises(ConfigError, match="holds other files, e.g. x, and no warpworm dataset"):
            check_output_dir(tmp_path / "full", resume=resume)
    (tmp_path / "full" / "manifest.json").write_text('{"format": "warpworm-dataset"}')
    with pytest.raises(ConfigError, match="it is not empty: it holds a warpworm dataset; use --resume"):
        check_output_dir(tmp_path / "full", resume=False)
    check_output_dir(tmp_path / "full", resume=True)
    (tmp_path / "other").mkdir()  # another tool's manifest.json does not make a folder a warpworm dataset
    (tmp_path / "other" / "manifest.json").write_text('{"name": "something else"}')
    with pytest.raises(ConfigError, match="no warpworm dataset"):
        check_output_dir(tmp_path / "other", resume=True)
    (tmp_path / "killed").mkdir()  # a job killed before its manifest: only its hidden lock / temporaries
    (tmp_path / "killed" / ".warpworm.lock").write_text("")
    check_output_dir(tmp_path / "killed", resume=True)
    check_output_dir(tmp_path / "new" / "deeper", resume=False)
    assert not (tmp_path / "new").exists()  # checking writes nothing
    # /proc is read-only for everyone, root included (chmod is not, for root)
    with pytest.raises(ConfigError, match="writable"):
        check_output_dir("/proc/warpworm-out", resume=False)


def test_cli_bad_config_exits_2_and_writes_nothing(tmp_path):
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "warpworm", "generate", "default", "--out", str(out), "sim.dt=-1",
                        "randomize.worm.gait=crawl"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "sim.dt: got -1; expected > 0" in r.stderr and "randomize.worm.gait: got 'crawl'" in r.stderr
    assert not out.exists()
    r = subprocess.run([sys.executable, "-m", "warpworm", "generate", "default", "--out", "/proc/ww"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--out" in r.stderr and "writable" in r.stderr
    # one line naming the refused folder and why (the OS's reason), and nothing on stdout: refused before any work
    assert r.stderr.count("\n") == 1 and "got '/proc/ww'" in r.stderr and "No such file or directory" in r.stderr
    assert r.stdout == ""


# The order of every randomize group as the datasets written before issue 25 list it in each shard's config_yaml
# (a resumed job compares that text; a reordered PARAM_SPECS would redo every shard of an old dataset). New
# parameters may only be appended.
PUBLISHED_ORDER = {
    "worm": ["a", "b", "l0", "sheet_density", "hinge_stiffness", "bar_stiffness", "valley_bar_stiffness", "damping",
             "mu_static", "mu_kinetic", "friction_backward_ratio", "floor_incline", "gravity", "dipole_density",
             "magnet_mass_density", "epm_moment", "epm_size_x", "epm_size_y", "epm_size_z", "ipm_moment_tail",
             "ipm_moment_centre", "ipm_moment_head", "ipm_diameter", "ipm_thickness", "wavelength", "amplitude",
             "closest_approach", "orientation", "cycle_period", "gait", "backward", "magnet_model", "hinge_damping",
             "waist_close_strain", "waist_stop_strain", "fold_limit_stiffness", "support_thickness",
             "closest_approach_scale", "wavelength_scale"],
    "camera": ["distance", "elevation", "azimuth", "roll", "fov_y", "lookat_jitter", "min_in_frame", "max_tries"],
    "light": ["elevation", "azimuth", "intensity", "ambient"],
    "color": ["worm_hue", "worm_saturation", "worm_value", "floor_hue", "floor_saturation", "floor_value",
              "background_value"],
    "texture": ["floor", "floor_scale", "worm"],
    "sensor": ["noise_std", "blur_sigma", "jpeg_quality", "brightness", "contrast"],
}


def test_parameter_order_of_published_datasets_is_kept():
    import yaml

    from warpworm.data.config import PARAM_SPECS

    written = yaml.safe_load(load_config("default").to_yaml())["randomize"]
    for group, names in PUBLISHED_ORDER.items():
        assert list(PARAM_SPECS[group])[:len(names)] == names, group
        assert list(written[group])[:len(names)] == names, group
