"""Step logs: the MCAP schema, writer and reader, and the Rerun viewer."""
