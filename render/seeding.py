"""Re-export of the counter-based generator's seed-keyed form, which lives in :mod:`warpworm.randomize` (the one
generator of the project). Kept for ``warpworm/commands/render.py``, which imports these names from here; new code
imports :func:`warpworm.randomize.seed_uniforms` / :func:`warpworm.randomize.derive_seeds`."""

from warpworm.randomize import derive_seeds
from warpworm.randomize import seed_uniforms as uniforms

__all__ = ["derive_seeds", "uniforms"]
