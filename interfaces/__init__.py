"""The contract every process shares: keys, messages, config, the CLI."""
