"""Top-level tools that tie the packages together: the CLI, the demo launcher, diagnostics."""
