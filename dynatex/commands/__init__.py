"""One module per ``dynatex`` subcommand: ``add_parser(subparsers, argv)`` and ``run(args) -> int``.

:data:`COMMANDS` names them with their one-line help, so that ``dynatex --help`` lists every
command without importing one, and ``dynatex CMD`` imports ``CMD``'s module alone
(:func:`dynatex.cli.build_parser`). This package imports nothing.
"""

#: subcommand -> its one-line help, in the order ``dynatex --help`` lists them
COMMANDS = {
    "analyze": "learn models from clips and write tile databases",
    "info": "describe a tile database",
    "play": "render frames of a texture to a video or PNG frames",
    "bench": "benchmark the player (fps, latency, roofline, numpy side by side)",
    "evaluate": "measure the quality of a synthesized texture against its source",
    "demo": "analyze a built-in sample, play every mode, write a video and a contact sheet",
    "export": "write a flipbook (atlas, motion vectors, engine sidecar) of a texture",
}
