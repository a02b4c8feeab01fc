"""Command-line entry points: each module's main(argv) is one command."""
