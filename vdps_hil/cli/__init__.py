"""Command line: a click root group with lazily loaded subcommands (only cli/ and hil/ open
devices or start threads)."""
