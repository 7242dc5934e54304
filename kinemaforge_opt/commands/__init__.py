"""Subcommands of the ``kinemaforge`` command: one module each, exposing ``register(subparsers)``."""
