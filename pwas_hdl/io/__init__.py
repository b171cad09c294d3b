"""Files in and out: CSV tables of plant data (csv_table) and atomic, all-or-nothing writes (atomic)."""
