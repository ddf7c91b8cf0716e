"""I/O at the edges: telemetry and detection CSVs, the TOML configuration, result writers."""
