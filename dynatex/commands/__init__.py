"""One module per ``dynatex`` subcommand: ``add_parser(subparsers, argv)`` and ``run(args) -> int``."""
