"""Sub-commands of the `antarium` command line (see `antarium.cli.COMMANDS`)."""
