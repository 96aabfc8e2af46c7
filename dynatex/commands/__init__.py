"""One module per ``dynatex`` subcommand: ``add_parser(subparsers)`` and ``run(args) -> int``."""
