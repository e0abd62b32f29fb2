"""Drive-cycle speed tables (package data; sources in README.md)."""
