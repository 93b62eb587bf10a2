"""CARL's ``carl.utils`` (the type aliases)."""
