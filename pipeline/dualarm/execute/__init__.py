"""Execution on the emulated humanoid in PyBullet (DIRECT mode)."""
