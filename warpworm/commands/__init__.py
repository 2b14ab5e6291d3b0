"""The CLI's subcommands, one module each (``HELP``, ``add_arguments(parser)``, ``main(args) -> int``).

``warpworm.cli`` imports every command module to build its parser, so a command imports the library inside its
``main`` (start-up time: building the parser loads none of the library's heavier modules, and one broken command
cannot stop the others); nothing in the library imports a command."""
