"""Helpers shared by the test suite (bundles, daemons, a daemon process)."""
