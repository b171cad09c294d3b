"""JSON Schemas of the file formats (one per format, owned by the module that reads and writes it)."""
