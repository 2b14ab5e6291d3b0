"""Dataset job configuration: YAML -> validated dataclasses (a pydantic v2 schema), with dotted command-line overrides.

The schema is the dataclasses of ``sections`` and ``dataset_config`` (their field docstrings are the documentation) and :data:`PARAM_SPECS` (every
randomizable parameter); ``warpworm config-schema`` exports it as a JSON Schema for editors.
All SI: m, s, rad, kg.

Every mistake (unknown key, wrong type, negative size, low > high, unknown gait, unwritable output folder) raises
:class:`ConfigError` *before any work*, with one line per problem naming the key path, the value given and what was
expected. Nothing is written by loading or validating a config. Building the dataclasses in code (e.g.
``dataclasses.replace``) does not validate: only YAML / mappings from outside go through :func:`config_from_dict`.

Modules: ``specs`` (PARAM_SPECS, BATCH_SHARED), ``sections`` (SimConfig, RenderConfig, OutputConfig),
``randomize_schema`` (the randomize groups), ``dataset_config`` (DatasetConfig), ``validate`` (config_from_dict,
check_option(s), messages), ``loading`` (read_yaml, apply_overrides, load_config).
Every public name is importable from here.
"""

from __future__ import annotations

from warpworm.data.config.dataset_config import DatasetConfig, schema_adapter
from warpworm.data.config.loading import apply_overrides, config_packaged_names, load_config, read_yaml
from warpworm.data.config.sections import RENDER_OFF_GROUPS, OutputConfig, RenderConfig, SimConfig
from warpworm.data.config.specs import BATCH_SHARED, PARAM_SPECS
from warpworm.data.config.validate import check_option, check_options, config_from_dict
from warpworm.errors import ConfigError
