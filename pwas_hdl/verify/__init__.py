"""Verification: replay of data through the generated RTL in a simulator, bit for bit against the bit-true model (simulation)."""
