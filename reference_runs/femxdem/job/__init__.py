"""Files copied into a job directory and run there by Debian's python3 (not by gransim's interpreter)."""
