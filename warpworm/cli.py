"""The ``warpworm`` command line: one subcommand per module in :mod:`warpworm.commands`.

Each command module defines ``HELP`` (one line), ``add_arguments(parser)`` and ``main(args) -> int``, and imports
what it needs at its top. A run of one command imports that command's module only; ``warpworm --help`` imports
none (each ``HELP`` is read from its source file); one broken command cannot take the others down.
"""

from __future__ import annotations

import argparse
import ast
import gc
import importlib
import importlib.util
import os
import sys
from collections.abc import Callable

# subcommand name -> module under warpworm.commands
COMMANDS = {
    "demo": "demo",
    "field": "field",
    "calibrate": "calibrate",
    "simulate": "simulate",
    "search-gait": "search_gait",
    "experiment": "experiment",
    "render": "render",
    "generate": "generate",
    "config-schema": "config_schema",
    "export-bop": "export_bop",
    "export-usd": "export_usd",
    "export-coco": "export_coco",
    "export-yolo": "export_yolo",
    "export-webdataset": "export_webdataset",
    "verify": "verify",
    "report": "report",
    "track": "track",
    "fit-track": "fit_track",
    "plan-clips": "plan_clips",
}


def _load(module_name: str):
    try:
        return importlib.import_module(f"warpworm.commands.{module_name}")
    except ModuleNotFoundError as exc:
        if exc.name == f"warpworm.commands.{module_name}":
            return None
        raise


def _help_of(module_name: str) -> str | None:
    """The ``HELP`` string of command module ``module_name``, read from its source without importing it (None when
    the module or the string is missing)."""
    spec = importlib.util.find_spec(f"warpworm.commands.{module_name}")
    if spec is None or not spec.origin:
        return None
    with open(spec.origin, encoding="utf-8") as f:
        tree = ast.parse(f.read())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "HELP" for t in node.targets):
            return ast.literal_eval(node.value)
    return None


class OneLineParser(argparse.ArgumentParser):
    """An argument mistake is one line on stderr (``warpworm CMD: error: ...; see warpworm CMD --help``), exit 2,
    as every other refused input (warpworm.commands.common), not argparse's usage block."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(commands: list[str] | None = None) -> argparse.ArgumentParser:
    """The CLI's parser: the subcommands ``commands`` with their arguments (each loads its module), or, by default,
    every subcommand named with its help line only (for ``warpworm --help`` and a mistyped name)."""
    from warpworm import __version__

    parser = OneLineParser(prog="warpworm", description="Batched simulation of magnetically actuated origami worms, "
                           "and labeled datasets from it. `warpworm COMMAND --help` for each command.")
    parser.add_argument("--version", action="version", version=f"warpworm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    for name, module_name in COMMANDS.items():
        if commands is None:
            text = _help_of(module_name)
            if text is not None:
                sub.add_parser(name, help=text, description=text)
            continue
        if name not in commands:
            continue
        module = _load(module_name)
        if module is None:
            continue
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_main=module.main)
    return parser


def main(argv: list[str] | None = None, *, parsed: Callable[[], None] | None = None) -> int:
    """Run the command ``argv`` names (default: the process's arguments) and return its exit status. ``parsed``: called
    once the command's module is imported and its arguments parsed, before the command runs."""
    # Warp's banner and module-load lines go to stdout; keep stdout for results (e.g. `--json`).
    # Set before any command module imports (and so initialises) Warp.
    from warpworm import quiet_warp

    quiet_warp()
    argv = sys.argv[1:] if argv is None else list(argv)
    named = next((a for a in argv if not a.startswith("-")), None)  # the top-level parser has no valued options
    parser = build_parser([named] if named in COMMANDS else None)
    args = parser.parse_args(argv)
    if parsed is not None:
        parsed()
    if not getattr(args, "_main", None):
        parser.print_help()
        return 2
    try:
        return int(args._main(args) or 0)
    except KeyboardInterrupt:
        print(f"warpworm {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the commands refuse bad input themselves (exit 2); this is a bug
        if os.environ.get("WARPWORM_DEBUG"):
            raise
        print(f"warpworm {args.command}: internal error: {type(exc).__name__}: {exc} (a bug: please report it with "
              "the output of the same command run with WARPWORM_DEBUG=1, which shows the traceback)", file=sys.stderr)
        return 1


def run() -> None:
    """The ``warpworm`` program (its console script and ``python -m warpworm``): :func:`main` with no garbage collection
    while it starts (the imports, Warp's builtins and our kernels' definitions make long-lived objects, not garbage:
    their full collections cost ~0.13 CPU-s per process for nothing), the start-up's objects then frozen and
    collection on for the command; and an exit whose final collection does not walk the objects alive at that point
    (``gc.freeze``: ~0.5 CPU-s per process; docs/render.md, "The rest of the job"). Only the program: a process that
    calls ``main`` many times (a test session) keeps collecting what it drops."""
    gc.disable()
    try:
        status = main(parsed=_collect_from_here)
    finally:
        gc.enable()
    gc.freeze()
    sys.exit(status)


def _collect_from_here() -> None:
    """The start-up's objects (Warp, the command's modules and kernels) into the permanent generation, then garbage
    collection on. The few unreachable objects the start-up made (2,366 of 164,240 for ``generate``) stay with them:
    less than the full collections that would find them cost."""
    gc.freeze()
    gc.enable()


if __name__ == "__main__":
    run()
