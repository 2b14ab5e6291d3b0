"""Re-export of the dataset pipeline's old module, for importers that have not switched yet
(``benchmarks/bench_dataset.py``). The code lives in :mod:`warpworm.job` (the job: plan, manifest, resume,
signals), :mod:`warpworm.shard` (one shard), :mod:`warpworm.stages` (the stages interface and ``WarpStages``),
:mod:`warpworm.sampling` (every randomized draw) and :mod:`warpworm.previews`.
"""

from .job import Interrupted, Summary, device_line, generate, plan_job, shard_plan  # noqa: F401
from .sampling import (  # noqa: F401
    appearance_draws,
    appearance_from_draws,
    dataset_cameras,
    draw_group,
    draw_worm,
    sensor_values,
    worm_params,
)
from .shard import ShardStats, root_attributes, run_shard  # noqa: F401
from .stages import DEFAULT_STAGES, SimResult, Stages, WarpStages, load_stages  # noqa: F401
