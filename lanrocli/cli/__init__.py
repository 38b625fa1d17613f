"""The ``lanro`` command line: the typer application (:mod:`lanrocli.cli.app`), one module per command,
what they display and ``lanro play``. It wires the layers below and knows nothing of how they work."""
