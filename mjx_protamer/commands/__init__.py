"""Subcommands of the `protamer` command line; each module has `register(subparsers)`."""
