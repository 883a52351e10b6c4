"""Subcommands of the ``twin`` command; each module exposes ``register(subparsers)``."""
