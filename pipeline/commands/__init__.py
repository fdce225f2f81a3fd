"""The rss6 commands: one module per command, each with its options and main(args) -> int."""
