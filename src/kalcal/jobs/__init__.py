"""File-level jobs behind the CLI commands: read inputs, call the numeric core, write outputs."""
