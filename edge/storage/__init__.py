"""Durable storage on the device: crash-safe files and the measurement history."""
