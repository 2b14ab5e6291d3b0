"""The whole config, :class:`DatasetConfig`: sections, counts, seed and the randomize groups, with the quantities
derived from them (shards, samples per trajectory) and its YAML form (every shard's ``config_yaml``)."""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from typing import Annotated

import yaml
from pydantic import AfterValidator, BeforeValidator, Field, TypeAdapter, ValidationInfo

from warpworm.data import randomize as rnd
from warpworm.data.config.randomize_schema import Randomize, with_defaults
from warpworm.data.config.sections import (SECTION, Int, OutputConfig, RenderConfig, SimConfig, Str, none_is_empty, problem,
                                           render_keys_left_out)


def _whole_trajectories(sim: SimConfig, info: ValidationInfo) -> SimConfig:
    shard_size, n = info.data.get("shard_size"), len(sim.frame_times)
    if shard_size is not None and shard_size % n:
        raise problem(f"got {shard_size}; expected a multiple of len(sim.frame_times) = {n} (a shard holds whole "
                       "trajectories)", path="shard_size")
    return sim


def _whole_trajectory_views(render: RenderConfig, info: ValidationInfo) -> RenderConfig:
    shard_size, sim = info.data.get("shard_size"), info.data.get("sim")
    k = render.views_per_frame
    if k > 1 and shard_size is not None and sim is not None and shard_size % (k * len(sim.frame_times)):
        raise problem(f"got {shard_size}; expected a multiple of render.views_per_frame * len(sim.frame_times) = "
                       f"{k} * {len(sim.frame_times)} (a shard holds whole trajectories)", path="shard_size")
    return render


# ---------------------------------------------------------------------------------------------------------------------
@dataclass
class DatasetConfig:
    """A dataset job: what to simulate and render, how much, and how it is stored (SI units)."""

    __pydantic_config__ = SECTION
    name: Str = "dataset"
    """Free text, stored in the files."""
    seed: Annotated[Int, Field(ge=0)] = 0
    """Master seed: sample i's values depend only on (seed, i)."""
    num_samples: Annotated[Int, Field(ge=1)] = 64
    """N: images (samples) in the dataset."""
    shard_size: Annotated[Int, Field(ge=1)] = 32
    """Samples per HDF5 shard; a multiple of len(sim.frame_times) (a shard holds whole trajectories)."""
    sim: Annotated[SimConfig, BeforeValidator(none_is_empty), AfterValidator(_whole_trajectories)] = \
        field(default_factory=SimConfig)
    """The batched simulation."""
    render: Annotated[RenderConfig, BeforeValidator(none_is_empty), AfterValidator(_whole_trajectory_views)] = \
        field(default_factory=RenderConfig)
    """Images."""
    output: Annotated[OutputConfig, BeforeValidator(none_is_empty)] = field(default_factory=OutputConfig)
    """The HDF5 files and previews."""
    randomize: Annotated[Randomize, BeforeValidator(none_is_empty), AfterValidator(with_defaults)] = \
        field(default_factory=dict)
    """group -> parameter -> distribution (a number is a constant; the forms: warpworm.data.randomize); parameters not
    named keep their defaults. Loaded, it holds every parameter of PARAM_SPECS as a warpworm.data.randomize.Distribution."""

    # ---- derived -------------------------------------------------------------------------------------------------
    @property
    def frames_per_trajectory(self) -> int:
        return len(self.sim.frame_times)

    @property
    def samples_per_trajectory(self) -> int:
        """K * F: every view (``render.views_per_frame``) of every frame of one simulated world."""
        return self.render.views_per_frame * len(self.sim.frame_times)

    @property
    def num_shards(self) -> int:
        return -(-self.num_samples // self.shard_size)

    def shard_range(self, k: int) -> tuple[int, int]:
        """Sample ids [start, stop) of shard k: always [k*S, min((k+1)*S, N)), whatever the workers."""
        return k * self.shard_size, min((k + 1) * self.shard_size, self.num_samples)

    def flat_distributions(self) -> dict[str, rnd.Distribution]:
        """'group.name' -> distribution."""
        return {f"{g}.{n}": d for g, params in self.randomize.items() for n, d in params.items()}

    def to_dict(self) -> dict:
        return {
            "name": self.name, "seed": self.seed, "num_samples": self.num_samples, "shard_size": self.shard_size,
            "sim": {k: v for k, v in dataclasses.asdict(self.sim).items() if not (k == "frame_unit" and v == "s")},
            # views_per_frame = 1 is left out, so the files' config_yaml stays that of before the option
            "render": {k: v for k, v in dataclasses.asdict(self.render).items()
                       if not (k == "views_per_frame" and v == 1) and k not in render_keys_left_out(self.render)},
            "output": dataclasses.asdict(self.output),
            "randomize": {g: {n: dist.to_yaml() for n, dist in p.items()} for g, p in self.randomize.items()},
        }

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False)


@functools.cache
def schema_adapter() -> TypeAdapter:
    """pydantic's validator (and JSON Schema) of DatasetConfig, built on first use (0.3 s, not paid by processes that
    only import this module)."""
    return TypeAdapter(DatasetConfig)
