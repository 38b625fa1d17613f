"""The ``lanro`` commands, one module per group of them; :mod:`lanrocli.cli.app` puts them together."""
