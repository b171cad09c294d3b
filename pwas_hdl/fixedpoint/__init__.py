"""Fixed point: word formats and input scaling (formats), the bit-true model of the circuit (bittrue), the weight memory layout (memory_layout)."""
