"""Subcommands of the sphere-twin CLI, one module each with register(subparsers)."""
