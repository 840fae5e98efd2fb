"""Tests that need a real Linux vcan0 (a package, so its conftest does not shadow tests/conftest.py)."""
