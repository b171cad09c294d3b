"""Tool flows: where the external tools are (toolchain), synthesis and place and route (synthesis), timing closure (timing_closure), word-length exploration (explore)."""
