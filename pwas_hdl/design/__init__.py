"""The generated design: the generate command (generate), the manifest that describes a design folder (manifest), the human-readable report (report)."""
