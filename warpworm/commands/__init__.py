"""The CLI's subcommands, one module each (``HELP``, ``add_arguments(parser)``, ``main(args) -> int``).

``warpworm.cli`` imports every command module to build its parser, so a command imports the library inside its
``main`` (start-up time: ``warpworm --help`` loads no Warp, h5py or pydantic); nothing in the library imports a
command."""
