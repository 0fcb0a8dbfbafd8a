"""Sinks for interface values: the MCAP recorder (NDJSON and tables live in cli/output)."""
