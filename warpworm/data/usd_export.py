"""Shim (issue 42): the USD exporter is :mod:`warpworm.data.export_usd`, beside the other exporters; this old name
stays importable until the branches of the time are merged, then goes."""

from warpworm.data.export_usd import *  # noqa: F401,F403
from warpworm.data.export_usd import compliance_errors, export_usd, read_points  # noqa: F401
