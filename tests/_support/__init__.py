"""Helpers of the test modules (not tests themselves)."""
