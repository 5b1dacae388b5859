"""Authenticated updates: Ed25519 signatures (pure Python), key files, the device's update policy."""
