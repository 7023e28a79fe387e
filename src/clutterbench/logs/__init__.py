"""Episode logs."""
